"""An ice field of floes with a size distribution: square floes of edge a drawn from a distribution, a given
thickness, random yaw, packed without overlap to a target concentration over the channel (seeded, recorded).

Packing (a shelf packing along the channel, then spread and turned):

1. Edges are drawn (``uniform`` between ``size_min_m`` and ``size_max_m``, or ``lognormal`` with median
   ``size_m`` and log-standard deviation ``size_sigma``, cut to [``size_min_m``, ``size_max_m``]) until their
   plan areas a^2 sum to the target c W L; the last edge is trimmed so the sum is the target (it stays within the
   bounds, or is dropped and the others scaled by less than its share).
2. Largest first, the floes fill columns across the channel, each floe a^2 in a slot a + g wide (g =
   ``gap_fraction`` of the smallest edge, so no two floes touch), a column as wide as its largest floe plus g.
   Each column is filled to the same fraction of the width as the columns' widths fill the channel's length
   (the fraction tried in steps of 0.01), so the free room lies alike along and across the channel, not in
   lanes. The columns are shuffled along the channel, so sizes mix along it while a column holds floes of one
   size.
3. The slack left across each column and along the channel is shared out evenly: each floe sits in a slot
   (column width x its share of the column). Its yaw is drawn uniformly within what its slot allows (a square
   of edge a turned by theta needs a (cos theta + sin theta) on each side, so a dense field turns little: at
   88 % the floes turn a few degrees, at 50 % freely), and its centre is shifted at random within the slot's
   remaining room.

The plan-area concentration sum a^2 / (W L) is the target to the trimming of step 1 (well within 1 %). A target
the columns cannot hold (their widths sum past the channel's length) is refused with the largest that fits.
Floes float at their hydrostatic draught rho_ice / rho_water x thickness.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from iceresist.errors import InputError

#: Distributions of the floe edge.
DISTRIBUTIONS = ("uniform", "lognormal")


@dataclass(frozen=True)
class IceField:
    """Floe centres (n, 3) m, edges (n,) m, yaw (n,) rad about z, one thickness, and what produced them."""

    centres_m: np.ndarray
    sizes_m: np.ndarray
    yaw_rad: np.ndarray
    thickness_m: float
    width_m: float
    length_m: float
    start_x_m: float
    distribution: str
    seed: int
    gap_m: float
    columns: int
    info: dict = field(default_factory=dict)

    @property
    def count(self) -> int:
        return len(self.centres_m)

    @property
    def concentration(self) -> float:
        """Plan-area fraction of the channel covered by floes."""
        return float((self.sizes_m ** 2).sum() / (self.width_m * self.length_m))

    @property
    def cube_m(self) -> float:
        """The median floe edge (the size scale where one number is asked for)."""
        return float(np.median(self.sizes_m))

    @property
    def n_along(self) -> int:
        return self.columns

    @property
    def n_across(self) -> int:
        return int(self.info.get("most_per_column", 0))

    @property
    def jitter_m(self) -> float:
        return 0.0

    def corners_xy(self) -> np.ndarray:
        """(n, 4, 2) plan corners of every floe, for pictures and overlap checks."""
        return floe_corners(self.centres_m[:, :2], self.sizes_m, self.yaw_rad)


def floe_corners(centres_xy: np.ndarray, sizes_m: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """(n, 4, 2) corners of squares of edge ``sizes_m`` turned by ``yaw_rad`` about their centres."""
    sq = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * 0.5
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    R = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (n, 2, 2)
    return centres_xy[:, None, :] + np.einsum("nij,kj->nki", R, sq) * sizes_m[:, None, None]


def _draw_sizes(rng, distribution: str, target_area: float, *, median_m: float, sigma: float, lo: float,
                hi: float) -> np.ndarray:
    sizes, area = [], 0.0
    while area < target_area:
        if distribution == "uniform":
            a = rng.uniform(lo, hi)
        else:
            a = float(np.clip(median_m * math.exp(sigma * rng.standard_normal()), lo, hi))
        sizes.append(a)
        area += a * a
        if len(sizes) > 2_000_000:
            raise InputError("ice.size_min_m: more than two million floes; give larger floes or a smaller channel")
    last2 = target_area - (area - sizes[-1] ** 2)  # what the last floe may still cover
    if last2 >= lo * lo:
        sizes[-1] = math.sqrt(last2)
        out = np.array(sizes)
    else:  # drop it; the others grow by less than its share (at most one floe's area)
        out = np.array(sizes[:-1]) * math.sqrt(target_area / (area - sizes[-1] ** 2))
    return out


def ice_field(*, width_m: float, length_m: float, concentration: float, distribution: str, size_m: float,
              size_min_m: float | None = None, size_max_m: float | None = None, size_sigma: float = 0.3,
              thickness_m: float | None = None, yaw: str = "random", start_x_m: float = 0.0,
              centre_y_m: float = 0.0, water_level_m: float = 0.0, ice_density_kg_m3: float = 950.0,
              water_density_kg_m3: float = 1000.0, gap_fraction: float = 0.02, seed: int = 0) -> IceField:
    """Floes of a size distribution packed over a channel from x = ``start_x_m``, centred on ``centre_y_m``
    (module docstring). Bad input: :class:`InputError` naming the ``ice.`` key."""
    if distribution not in DISTRIBUTIONS:
        raise InputError(f"ice.size_distribution: {distribution!r}; use one of {', '.join(DISTRIBUTIONS)}")
    if not 0 < concentration <= 1:
        raise InputError(f"ice.concentration: must lie in (0, 1] (got {concentration})")
    for key, v in (("ice.channel_width_m", width_m), ("ice.channel_length_m", length_m), ("ice.size_m", size_m)):
        if not v > 0:
            raise InputError(f"{key}: must be > 0 (got {v})")
    lo = float(size_min_m if size_min_m is not None else (0.5 * size_m if distribution == "lognormal" else size_m))
    hi = float(size_max_m if size_max_m is not None else (2.0 * size_m if distribution == "lognormal" else size_m))
    if not 0 < lo <= hi:
        raise InputError(f"ice.size_min_m: {lo} m must be > 0 and at most ice.size_max_m ({hi} m)")
    if hi > width_m:
        raise InputError(f"ice.size_max_m: {hi} m floes do not fit across the {width_m} m channel; give a smaller "
                         f"ice.size_max_m")
    h = float(thickness_m if thickness_m is not None else size_m)
    if not h > 0:
        raise InputError(f"ice.thickness_m: must be > 0 (got {h})")
    if ice_density_kg_m3 >= water_density_kg_m3:
        raise InputError(f"ice.density_kg_m3: {ice_density_kg_m3} kg/m^3 does not float in water of "
                         f"{water_density_kg_m3} kg/m^3")
    rng = np.random.default_rng(seed)
    sizes = _draw_sizes(rng, distribution, concentration * width_m * length_m, median_m=size_m, sigma=size_sigma,
                        lo=lo, hi=hi)
    gap = gap_fraction * lo

    # largest first into columns across the channel, each filled to the same fraction of the width as the
    # columns fill the length, so the free room is shared alike along and across (no lanes)
    order = np.argsort(-sizes, kind="stable")

    def fill(fraction):
        columns, col, used = [], [], 0.0
        for i in order:
            if col and used + sizes[i] + gap > fraction * width_m:
                columns.append(col)
                col, used = [], 0.0
            col.append(i)
            used += sizes[i] + gap
        columns.append(col)
        return columns, np.array([sizes[c].max() + gap for c in columns])

    best = None
    for fraction in np.arange(0.30, 1.0001, 0.01):
        columns, widths = fill(fraction)
        along = widths.sum() / length_m
        if along <= 1.0 and (best is None or abs(along - fraction) < best[0]):
            best = (abs(along - fraction), columns, widths)
    columns, widths = (best[1], best[2]) if best is not None else fill(1.0)
    if widths.sum() > length_m:
        fits = concentration * length_m / widths.sum()
        raise InputError(f"ice.concentration: {concentration:g} cannot be packed with these floes (their columns "
                         f"need {widths.sum():.4g} m of the {length_m:g} m channel); give at most about "
                         f"{math.floor(100 * fits) / 100:g}, or narrow the sizes (ice.size_min_m, ice.size_max_m)")
    perm = rng.permutation(len(columns))
    columns, widths = [columns[k] for k in perm], widths[perm]
    slack_x = (length_m - widths.sum()) / len(columns)

    n = len(sizes)
    centres = np.zeros((n, 3))
    yaw_out = np.zeros(n)
    x = start_x_m
    for col, w in zip(columns, widths):
        slot_x = w + slack_x
        a = sizes[col]
        slack_y = (width_m - (a + gap).sum()) / len(col)
        slot_y = a + gap + slack_y
        y = centre_y_m - 0.5 * width_m + np.concatenate([[0.0], np.cumsum(slot_y)[:-1]])
        room = np.minimum(slot_x, slot_y) - gap  # the side a turned floe may take
        if yaw == "random":
            ratio = np.clip(room / (a * math.sqrt(2.0)), 0.0, 1.0)
            tmax = np.where(ratio >= 1.0, math.pi / 4, np.arcsin(ratio) - math.pi / 4)
            theta = rng.uniform(-1.0, 1.0, len(col)) * np.maximum(tmax, 0.0)
        else:
            theta = np.zeros(len(col))
        side = a * (np.abs(np.cos(theta)) + np.abs(np.sin(theta)))  # plan extent of the turned floe
        free_x = np.maximum(slot_x - gap - side, 0.0)
        free_y = np.maximum(slot_y - gap - side, 0.0)
        centres[col, 0] = x + 0.5 * slot_x + rng.uniform(-0.5, 0.5, len(col)) * free_x
        centres[col, 1] = y + 0.5 * slot_y + rng.uniform(-0.5, 0.5, len(col)) * free_y
        yaw_out[col] = theta
        x += slot_x
    centres[:, 2] = water_level_m + h * (0.5 - ice_density_kg_m3 / water_density_kg_m3)
    info = {"most_per_column": int(max(len(c) for c in columns)), "size_min_m": lo, "size_max_m": hi,
            "size_sigma": float(size_sigma), "yaw": yaw, "largest_yaw_deg": float(np.degrees(np.abs(yaw_out)).max())}
    return IceField(centres_m=centres, sizes_m=sizes, yaw_rad=yaw_out, thickness_m=h, width_m=float(width_m),
                    length_m=float(length_m), start_x_m=float(start_x_m), distribution=distribution, seed=int(seed),
                    gap_m=float(gap), columns=len(columns), info=info)


def overlapping_pairs(corners: np.ndarray) -> list[tuple[int, int]]:
    """Pairs of convex plan polygons (n, 4, 2) that overlap (separating-axis test on near neighbours)."""
    from scipy.spatial import cKDTree

    centre = corners.mean(axis=1)
    reach = np.linalg.norm(corners - centre[:, None], axis=2).max()
    out = []
    for i, j in cKDTree(centre).query_pairs(2.0 * reach):
        separated = False
        for poly in (corners[i], corners[j]):
            edges = np.roll(poly, -1, axis=0) - poly
            for e in edges:
                nrm = np.array([-e[1], e[0]])
                pi, pj = corners[i] @ nrm, corners[j] @ nrm
                if pi.max() <= pj.min() or pj.max() <= pi.min():
                    separated = True
                    break
            if separated:
                break
        if not separated:
            out.append((int(i), int(j)))
    return out
