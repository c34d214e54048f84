"""Post-processing of ice-force records: steady-window mean with its uncertainty, full-scale
conversion by Froude similarity, and the comparison with the FSICR R_CH (paper section 4.2, table 2).

The statistics work on any record read back from the HDF5 time series (numpy, scipy and pandas only).
:mod:`iceresist.post.case` analyses one case file of a sweep and :mod:`iceresist.post.sweeptable` builds a
sweep's table from its case files; they read files (:mod:`iceresist.io`) and the ship's geometry
(:mod:`iceresist.ship`), never the models or the driver, and they write nothing.
"""

from iceresist.post.comparison import (
    COLUMN_LABELS,
    case_ratio,
    comparison_row,
    comparison_table,
    format_comparison_table,
)
from iceresist.post.resistance import (
    WindowHalves,
    ice_resistance_from_timeseries,
    resistance_from_contact_force,
    window_halves,
    window_parts,
)
from iceresist.post.scaling import (
    PAPER_SCALE,
    RHO_FRESH_WATER_KG_M3,
    RHO_SEA_WATER_KG_M3,
    force_to_full_scale,
    force_to_model_scale,
    length_to_full_scale,
    length_to_model_scale,
    power_to_full_scale,
    power_to_model_scale,
    speed_to_full_scale,
    speed_to_model_scale,
    time_to_full_scale,
    time_to_model_scale,
)
from iceresist.post.statistics import (
    BatchMeans,
    SteadyMean,
    autocorrelation,
    batch_means,
    choose_n_batches,
    integrated_autocorrelation_time,
    steady_mean,
)
from iceresist.post.window import WindowSamples, select_window

__all__ = [
    "COLUMN_LABELS",
    "PAPER_SCALE",
    "RHO_FRESH_WATER_KG_M3",
    "RHO_SEA_WATER_KG_M3",
    "BatchMeans",
    "SteadyMean",
    "WindowHalves",
    "WindowSamples",
    "autocorrelation",
    "batch_means",
    "case_ratio",
    "choose_n_batches",
    "comparison_row",
    "comparison_table",
    "force_to_full_scale",
    "force_to_model_scale",
    "format_comparison_table",
    "ice_resistance_from_timeseries",
    "integrated_autocorrelation_time",
    "length_to_full_scale",
    "length_to_model_scale",
    "power_to_full_scale",
    "power_to_model_scale",
    "resistance_from_contact_force",
    "select_window",
    "speed_to_full_scale",
    "speed_to_model_scale",
    "steady_mean",
    "time_to_full_scale",
    "time_to_model_scale",
    "window_halves",
    "window_parts",
]
