"""The B-063 model hull of the paper (section 3, figure 2) built from parameters as a convex polyhedron.

B-063 (NMRI) is a double-ended, wall-sided hull: a parallel middle body of length LPAR between two wedge
ends whose waterline half angle is alpha, each end bounded by two plane faces raked at the stem angle phi
(30 deg Bow A, 45 deg Bow B). A plane bow face contains the raked stem line, so every buttock of the face has
the stem's rake: phi2 (at B/4) = phi1 (at the centreline), as the paper's table 1 states. Bottom and deck
are hexagons: the bottom is the waterline hexagon moved in by T / tan(phi) at each end, the deck the
waterline hexagon moved out by f / tan(phi) (f the freeboard), so the hull is a hexagonal pyramid
trapezoid with plane faces.

Ship frame: x forward, y to port, z up; origin on the centreline at the keel (z = 0) below the forward
perpendicular (the stem at the waterline, x = 0). The bow is at +x, the other end (the stern) at -x.

Inputs are the length overall (deck, 3.5 m), beam, draught, LPAR, alpha and the two rakes; the freeboard
follows from the length overall: f = (LOA - L_wl) / (cot phi_bow + cot phi_stern), L_wl = LPAR + B / tan(alpha).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import fsicr
from iceresist.errors import InputError

#: Paper's scale ratio (model : full = 1 : 25).
B063_SCALE = 25.0
#: Paper table 1 (full scale) for Bow A and Bow B.
PAPER_TABLE1 = {
    "A": {"L_m": 76.0, "LPAR_m": 45.7, "B_m": 17.5, "T_m": 11.0, "Awf_m2": 96.25, "alpha_deg": 30.0,
          "phi1_deg": 30.0, "phi2_deg": 30.0},
    "B": {"L_m": 76.0, "LPAR_m": 45.7, "B_m": 17.5, "T_m": 11.0, "Awf_m2": 96.25, "alpha_deg": 30.0,
          "phi1_deg": 45.0, "phi2_deg": 45.0},
}
BOW_ANGLES_DEG = {"A": 30.0, "B": 45.0}


def _cot(deg: float) -> float:
    return 1.0 / math.tan(math.radians(deg))


@dataclass(frozen=True)
class HullGeometry:
    """A B-063-type hull at model scale (metres, degrees). See the module docstring for the frame."""

    length_overall_m: float = 3.5
    beam_m: float = 0.7
    draught_m: float = 0.44
    parallel_length_m: float = 45.7 / B063_SCALE
    waterline_angle_deg: float = 30.0
    bow_rake_deg: float = 30.0
    stern_rake_deg: float = 45.0

    def __post_init__(self):
        for name in ("length_overall_m", "beam_m", "draught_m"):
            if not getattr(self, name) > 0:
                raise InputError(f"ship.{name}: must be > 0 (got {getattr(self, name)})")
        if self.parallel_length_m < 0:
            raise InputError(f"ship.parallel_length_m: must be >= 0 (got {self.parallel_length_m})")
        for name in ("waterline_angle_deg", "bow_rake_deg", "stern_rake_deg"):
            v = getattr(self, name)
            if not 0 < v < 90:
                raise InputError(f"ship.{name}: must lie in (0, 90) degrees (got {v})")
        if self.freeboard_m <= 0:
            raise InputError(f"ship.length_m: {self.length_overall_m} m leaves no freeboard: the waterline alone "
                             f"is {self.waterline_length_m:.4g} m long; give a longer length overall or a longer "
                             f"ship.parallel_length_m")
        if self.bottom_parallel_length_m < 0:
            raise InputError(f"ship.draught_m: {self.draught_m} m is too deep for these rakes: the raked ends "
                             f"cross below the waterline (parallel bottom {self.bottom_parallel_length_m:.3g} m)")

    # -- derived dimensions ------------------------------------------------------------------------------
    @property
    def end_length_m(self) -> float:
        """Waterline length of one wedge end, (B/2) / tan(alpha) (L_BOW)."""
        return 0.5 * self.beam_m / math.tan(math.radians(self.waterline_angle_deg))

    @property
    def waterline_length_m(self) -> float:
        """L_wl = LPAR + 2 (B/2) / tan(alpha): the length at the draught (L between perpendiculars)."""
        return self.parallel_length_m + 2.0 * self.end_length_m

    @property
    def freeboard_m(self) -> float:
        """Deck height above the waterline that makes the deck ``length_overall_m`` long."""
        return (self.length_overall_m - self.waterline_length_m) / (_cot(self.bow_rake_deg)
                                                                    + _cot(self.stern_rake_deg))

    @property
    def depth_m(self) -> float:
        """Keel to deck."""
        return self.draught_m + self.freeboard_m

    @property
    def midship_area_m2(self) -> float:
        """Immersed midship section B T (m^2): the hull is wall-sided with a flat bottom."""
        return self.beam_m * self.draught_m

    @property
    def prismatic_length_m(self) -> float:
        """V / A_s: displaced volume over the midship section (C_P L_wl), the spacing of the hull's long-wave
        source and sink (:mod:`iceresist.ship.tank`)."""
        return self.volume_m3() / self.midship_area_m2

    @property
    def bottom_parallel_length_m(self) -> float:
        return self.parallel_length_m - self.draught_m * (_cot(self.bow_rake_deg) + _cot(self.stern_rake_deg))

    @property
    def bow_overhang_m(self) -> float:
        """How far the deck reaches ahead of the stem at the waterline, f / tan(phi_bow)."""
        return self.freeboard_m * _cot(self.bow_rake_deg)

    def _hexagon(self, z: float) -> np.ndarray:
        """The hull section at height z (a hexagon; 6 x 3 vertices)."""
        dz = z - self.draught_m  # above the waterline > 0: the raked ends reach out
        half = 0.5 * self.beam_m
        x_bow = dz * _cot(self.bow_rake_deg)
        x_stern = -self.waterline_length_m - dz * _cot(self.stern_rake_deg)
        x_fs = x_bow - self.end_length_m
        x_as = x_stern + self.end_length_m
        return np.array([[x_bow, 0, z], [x_fs, half, z], [x_as, half, z], [x_stern, 0, z], [x_as, -half, z],
                         [x_fs, -half, z]], dtype=float)

    def vertices(self) -> np.ndarray:
        """The 12 vertices of the convex hull (bottom hexagon, then deck hexagon), ship frame, metres."""
        return np.vstack([self._hexagon(0.0), self._hexagon(self.depth_m)])

    def mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """The closed hull surface as triangles: (vertices (12, 3) m, faces (20, 3)), normals outward."""
        from scipy.spatial import ConvexHull

        v = self.vertices()
        faces = ConvexHull(v).simplices.copy()
        t = v[faces]
        inward = np.einsum("ij,ij->i", np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), t[:, 0] - v.mean(axis=0)) < 0
        faces[inward] = faces[inward][:, ::-1]
        return v, faces

    def waterline_polygon(self) -> np.ndarray:
        """The waterline hexagon (x, y) at the draught, for pictures."""
        return self._hexagon(self.draught_m)[:, :2]

    def volume_m3(self) -> float:
        """Displacement volume below the waterline (m^3): prismatoid of the bottom and waterline hexagons."""
        def area(z):
            p = self._hexagon(z)[:, :2]
            x, y = p[:, 0], p[:, 1]
            return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        T = self.draught_m
        return T / 6.0 * (area(0.0) + 4.0 * area(T / 2) + area(T))  # exact: area is quadratic in z

    # -- FSICR inputs -------------------------------------------------------------------------------------
    def fsicr_inputs(self, scale: float = B063_SCALE) -> dict:
        """The FSICR R_CH inputs of this hull at full scale (lengths x scale, areas x scale^2).

        L = L_wl; LPAR; LBOW = (B/2) / tan(alpha); Awf = the waterplane area of the wedge bow, LBOW B / 2;
        alpha; phi1 = phi2 = the bow rake (plane bow faces); B; T.
        """
        s = float(scale)
        lbow = self.end_length_m
        return {"L_m": self.waterline_length_m * s, "LPAR_m": self.parallel_length_m * s,
                "LBOW_m": lbow * s, "B_m": self.beam_m * s, "T_m": self.draught_m * s,
                "Awf_m2": 0.5 * lbow * self.beam_m * s * s, "alpha_deg": self.waterline_angle_deg,
                "phi1_deg": self.bow_rake_deg, "phi2_deg": self.bow_rake_deg}

    def fsicr_ship(self, scale: float = B063_SCALE, name: str = "B-063 (geometry)"):
        """An :class:`fsicr.Ship` from :meth:`fsicr_inputs`."""
        return fsicr.Ship(name=name, **self.fsicr_inputs(scale))


def b063_hull(bow: str = "A", *, length_overall_m: float = 3.5, beam_m: float = 0.7, draught_m: float = 0.44,
              parallel_length_m: float = 45.7 / B063_SCALE, waterline_angle_deg: float = 30.0,
              bow_rake_deg: float | None = None, stern_rake_deg: float | None = None) -> HullGeometry:
    """The B-063 model hull going ahead with ``bow`` ``"A"`` (30 deg) or ``"B"`` (45 deg); the stern is the
    other end of the same double-ended hull unless ``stern_rake_deg`` is given."""
    key = str(bow).upper()
    if key not in BOW_ANGLES_DEG:
        raise InputError(f"ship bow: {bow!r} is not a B-063 bow; use 'A' (30 deg) or 'B' (45 deg)")
    other = "B" if key == "A" else "A"
    return HullGeometry(length_overall_m=length_overall_m, beam_m=beam_m, draught_m=draught_m,
                        parallel_length_m=parallel_length_m, waterline_angle_deg=waterline_angle_deg,
                        bow_rake_deg=BOW_ANGLES_DEG[key] if bow_rake_deg is None else bow_rake_deg,
                        stern_rake_deg=BOW_ANGLES_DEG[other] if stern_rake_deg is None else stern_rake_deg)
