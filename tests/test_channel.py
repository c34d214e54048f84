"""Brash-ice channel: the paper's cube counts, coverage, jitter, flotation."""

import numpy as np
import pytest

from iceresist.errors import InputError
from iceresist.ship.channel import channel_layout


@pytest.mark.parametrize("c,ny,nx", [(0.68, 28, 112), (0.88, 32, 128), (0.50, 24, 96)])
def test_paper_counts(c, ny, nx):
    lay = channel_layout(concentration=c)
    assert (lay.n_across, lay.n_along, lay.count) == (ny, nx, ny * nx)
    assert lay.concentration == pytest.approx(c, abs=0.011)


def test_count_2034_literal():
    lay = channel_layout(count=2034)
    assert lay.count == 2034
    assert lay.concentration == pytest.approx(2034 * 0.041**2 / (1.39 * 5.56))  # 44 %, not 50 %


def test_inside_channel_no_overlap_and_floating():
    lay = channel_layout(concentration=0.88, start_x_m=4.0, centre_y_m=0.695, water_level_m=1.11, jitter_m=1.0,
                         seed=3)
    p, a = lay.centres_m, lay.cube_m
    assert p[:, 0].min() - a / 2 >= 4.0 and p[:, 0].max() + a / 2 <= 4.0 + 5.56
    assert p[:, 1].min() - a / 2 >= 0.0 and p[:, 1].max() + a / 2 <= 1.39 + 1e-12
    d = np.abs(p[:, None, :2] - p[None, :, :2]).max(axis=2) + np.eye(len(p)) * 1.0
    assert d.min() >= a - 1e-12  # no two cubes overlap (Chebyshev distance of centres >= edge)
    assert np.allclose(p[:, 2], 1.11 + a * (0.5 - 0.95))  # hydrostatic draught 0.95 a
    assert lay.jitter_m == pytest.approx(min(lay.gap_across_m, lay.gap_along_m) / 2)


def test_jitter_is_seeded():
    a = channel_layout(concentration=0.5, jitter_m=0.002, seed=1).centres_m
    b = channel_layout(concentration=0.5, jitter_m=0.002, seed=1).centres_m
    c = channel_layout(concentration=0.5, jitter_m=0.002, seed=2).centres_m
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_refusals():
    with pytest.raises(InputError, match="exactly one"):
        channel_layout(concentration=0.5, count=10)
    with pytest.raises(InputError, match="do not fit"):
        channel_layout(count=10**6)
