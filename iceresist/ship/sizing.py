"""The tank, the ice channel and the steady window of a ship case, sized from the hull (docs/OWN_SHIP.md).

The paper's tank was built around B-063 (3.5 m long, 0.7 m beam, 0.44 m draught at 1:25). Any other hull gets the
same tank in proportion to its own dimensions, so that its blockage, its depth over draught and the room behind its
stern and ahead of the channel are those of the paper's case, and its steady window is as long in hull lengths:

- across: tank width W = W_ref B / B_ref (the channel spans the tank unless a channel width is asked for, and a
  wider channel widens the tank);
- down: water depth h = h_ref T / T_ref, tank height H = H_ref T / T_ref;
- along: channel start x_c = x_c,ref L / L_ref (L the length overall), or more where the stern at the waterline would
  come closer to the aft wall than the reference's share of its waterline length; the window opens once the hull's lead-in is
  in the ice (its bow length when the preset's channel is shorter than the hull, its waterline length when
  longer) and runs w L_wl further to the channel's end, w the preset's own window over B-063's waterline length;
  channel length = lead-in + w L_wl; the tank ends max(L_x,ref L / L_ref, channel end + room_ref L / L_ref) from
  its aft wall, room_ref what the reference leaves ahead of its channel.

B-063 is one instance: every ratio is 1 and the numbers are the presets' own (``cases.toml``; tested). Tier 2
puts the same lengths on its lattice: the preset's cell scaled with the ice piece (so cells per piece stay), the
cell counts rounded up to whole level-0 blocks of :data:`BLOCK_CELLS`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from iceresist.errors import InputError

#: Lengths of the sized tank are rounded to this many decimals of a metre: the presets' numbers come back exactly.
ROUND_DIGITS = 6
#: The stem starts this far before the channel (m; the presets' rule).
START_GAP_M = 0.05
#: How much shorter than asked a window may be (m): the rounding of sized lengths.
SLACK_M = 1e-5
#: Cell counts of a refined tier-2 tank are whole multiples of this (its level-0 block).
BLOCK_CELLS = 8


@dataclass(frozen=True)
class Reference:
    """The reference hull and its tank, channel and window for one preset and tier (lengths in m at model scale)."""

    length_overall_m: float
    beam_m: float
    draught_m: float
    waterline_length_m: float
    end_length_m: float
    tank_m: tuple[float, float, float]
    water_depth_m: float
    channel_start_x_m: float
    channel_length_m: float
    ice_size_m: float

    @property
    def lead_in_whole_hull(self) -> bool:
        """Whether the window opens with the whole waterline in the ice (a channel longer than the hull)."""
        return self.channel_length_m > self.waterline_length_m

    @property
    def lead_in_m(self) -> float:
        return self.waterline_length_m if self.lead_in_whole_hull else self.end_length_m

    @property
    def window_hull_lengths(self) -> float:
        """The reference's steady window over its waterline length: the least a sized case may have."""
        return (self.channel_length_m - self.lead_in_m) / self.waterline_length_m

    @property
    def aft_room_m(self) -> float:
        """Between the aft wall and the stern at the waterline at the start."""
        return self.channel_start_x_m - START_GAP_M - self.waterline_length_m

    @property
    def room_ahead_m(self) -> float:
        return self.tank_m[0] - self.channel_start_x_m - self.channel_length_m


@dataclass(frozen=True)
class CaseTank:
    """A case's tank (x along the run, y across, z up), channel and steady window (stem positions), in m."""

    tank_m: tuple[float, float, float]
    water_depth_m: float
    channel_start_x_m: float
    channel_length_m: float
    channel_width_m: float
    window_m: tuple[float, float]

    @property
    def start_x_m(self) -> float:
        """Stem at t = 0: :data:`START_GAP_M` before the channel (the presets' rule)."""
        return _r(self.channel_start_x_m - START_GAP_M)

    @property
    def end_x_m(self) -> float:
        return self.channel_start_x_m + self.channel_length_m


def _r(x: float) -> float:
    return round(float(x), ROUND_DIGITS)


def size_case(hull, ref: Reference, *, ice_size_m: float | None = None,
              channel_width_m: float | None = None) -> CaseTank:
    """The tank, channel and window of ``hull`` (any object with ``length_overall_m``, ``beam_m``, ``draught_m``,
    ``waterline_length_m`` and ``end_length_m``) after the rules of the module docstring, against ``ref``."""
    rl = hull.length_overall_m / ref.length_overall_m
    rb = hull.beam_m / ref.beam_m
    rt = hull.draught_m / ref.draught_m
    width = ref.tank_m[1] * rb
    if channel_width_m is not None:
        width = max(width, float(channel_width_m))
    lead_in = hull.waterline_length_m if ref.lead_in_whole_hull else hull.end_length_m
    window = ref.window_hull_lengths * hull.waterline_length_m
    # the stern's room behind the stem's start in proportion to the waterline, never less than the reference's share
    start = _r(max(ref.channel_start_x_m * rl,
                   START_GAP_M + hull.waterline_length_m * (1.0 + ref.aft_room_m / ref.waterline_length_m)))
    length = _r(lead_in + window)
    # room ahead of the channel and the tank's length in proportion; never shorter than the reference's share
    tank_x = _r(max(ref.tank_m[0] * rl, start + length + ref.room_ahead_m * rl))
    tank = (tank_x, _r(width), _r(ref.tank_m[2] * rt))
    cw = _r(channel_width_m) if channel_width_m is not None else tank[1]
    return CaseTank(tank_m=tank, water_depth_m=_r(ref.water_depth_m * rt), channel_start_x_m=start,
                    channel_length_m=length, channel_width_m=cw, window_m=(_r(start + lead_in), _r(start + length)))


def lattice_cells(tank_m, dx_m: float, block: int = 1) -> list[int]:
    """Tier 2: cells along each axis to hold ``tank_m`` at ``dx_m``, rounded up to whole blocks of ``block`` cells
    (:data:`BLOCK_CELLS` on refined levels); a length within 1e-3 cells of a whole number keeps that number."""
    return [block * math.ceil(math.ceil(length / dx_m - 1e-3) / block) for length in tank_m]


def check_window(window_m: tuple[float, float], waterline_length_m: float, least_hull_lengths: float,
                 channel_length_m: float, lead_in_m: float) -> None:
    """Refuse a steady window shorter than ``least_hull_lengths`` waterline lengths (empty included), in one line
    naming the channel length that gives one."""
    x0, x1 = window_m
    need = least_hull_lengths * waterline_length_m
    if x1 - x0 >= need - SLACK_M:  # a sized channel rounded to the micrometre passes
        return
    fits = lead_in_m + need
    raise InputError(f"ice.channel_length_m: {channel_length_m:.4g} m leaves a steady window of {x1 - x0:.3g} m "
                     f"(stem from x = {x0:.4g} to {x1:.4g} m) for a hull of {waterline_length_m:.4g} m waterline, "
                     f"less than the {least_hull_lengths:.3g} hull lengths ({need:.3g} m) the mean needs; give "
                     f"ice.channel_length_m = {math.ceil(fits * 100) / 100:.2f} or more (or a steady window of your "
                     f"own, ship.steady_window_m)")
