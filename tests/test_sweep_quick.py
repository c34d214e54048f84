"""The quick sweeps of all six cases reproduce the paper's trends (minutes for tier 1, hours for tier 2 on a
2-core CPU: marked slow); two quick tier-1 cases (about 16 s each on a 2-core x86 VM) run in CI against their
measured mean forces, the bow trend and the FSICR order."""

import math

import numpy as np
import pytest

from iceresist.post.trends import fsicr_order, paper_trends
from iceresist.sweep import run_sweep


def assert_paper_trends(t, fsicr_factor: float | None = 3.0):
    """The paper's trends hold in the sweep table ``t``; ``fsicr_factor``: the full-scale resistance within this
    factor of FSICR R_CH either way (None: the trends alone)."""
    # rises with concentration (Bow A, 1 knot) and with speed (Bow A, 68 %); the steeper Bow B above Bow A
    for check in paper_trends(t):
        assert check.holds, f"{check.name}: {check.values()}"
    if fsicr_factor is None:
        return
    # full scale of the order of FSICR R_CH (within fsicr_factor either way)
    ok, lo, hi = fsicr_order(t, fsicr_factor)
    assert ok, f"simulated / FSICR from {lo:.2f} to {hi:.2f}"


@pytest.mark.slow
def test_quick_sweep_trends(tmp_path):
    assert_paper_trends(run_sweep("quick", 1, tmp_path, None, backend="cpu"))


@pytest.mark.slow
def test_quick_tier2_sweep_trends(tmp_path):
    """About 9 h on the 2-core VM (six cases of 1-2.5 h on 2 threads in the 0.9 m tank); minutes on a GPU.

    The trends alone (concentration, speed, Bow B above Bow A): the FSICR order is judged at tier 2 only on a grid
    the tier-2 ladder shows converged (block AMR, part 2). On the quick grid (3.1 cells per cube) the force is not
    converged (docs/SHIP.md, "Why the quick tier 2 is low": its 50 % case gives 0.06 x FSICR), and the report
    states the value and that it is unconverged."""
    assert_paper_trends(run_sweep("quick", 2, tmp_path, None), fsicr_factor=None)


#: Quick preset, tier 1: mean ice force [N] and the half width of its own 95 % batch-means interval [N] as
#: measured on a 2-core x86 VM (AMD EPYC, 2026-12-07, the face dashpot; A: 9.395 +- 1.075 N, batch means; B: 13.467 +-
#: 2.962 N, 5 batches; with the sphere-pair dashpot before: A 10.027 +- 1.512 N, B 13.712 +- 2.781 N). The
#: run is deterministic on one machine, but another floating-point order (another CPU, e.g. an Intel Xeon with
#: AVX-512) is another sample of the same chaotic run, so each case is held to its pinned mean
#: within the two intervals added in quadrature (two independent samples of one mean), and its interval's width to
#: the 99 % range of the ratio of two independent batch-means widths, sqrt(F(B - 1, B - 1)): a change the intervals
#: cannot tell from noise passes, a change of the physics beyond them fails. Planted: the tier-1 water drag x4
#: (iceresist.dem.hydro) gives A 23.6 +- 6.8 N and B 31.9 +- 7.6 N (both fail).
QUICK_PINS = {"A-c68-v1.0": (9.395, 1.075), "B-c68-v1.0": (13.467, 2.962)}


@pytest.fixture(scope="module")
def quick_case(tmp_path_factory):
    """The table row of one quick tier-1 case (whole preset, no overrides), run once per module."""
    rows = {}

    def run(case):
        if case not in rows:
            out = tmp_path_factory.mktemp(case)
            rows[case] = run_sweep("quick", 1, out, [case], backend="cpu").iloc[0]
        return rows[case]

    return run


@pytest.mark.parametrize("case", list(QUICK_PINS))
def test_quick_case_mean_force_within_its_own_interval_of_the_pinned_value(quick_case, case):
    from scipy import stats

    row = quick_case(case)
    mean, half = QUICK_PINS[case]
    both = math.hypot(half, row.ci95_N)
    assert abs(row.mean_force_N - mean) <= both, \
        f"{case}: {row.mean_force_N:.3f} +- {row.ci95_N:.3f} N, pinned {mean} +- {half} N"
    # the interval itself: its width a sample of the same spread as the pinned one (module comment above)
    dof = int(row.n_batches) - 1
    lo, hi = np.sqrt(stats.f.ppf([0.005, 0.995], dof, dof))
    assert lo <= row.ci95_N / half <= hi, f"{case}: half width {row.ci95_N:.3f} N against {half} N ({lo:.2f}-{hi:.2f})"
    # the full-scale resistance against FSICR R_CH within 3 x either way (measured 0.54 and 0.60)
    assert 1 / 3 <= row.ratio_sim_FSICR <= 3


def test_quick_bow_b_above_bow_a(quick_case):
    """The paper's steeper Bow B above Bow A at 68 %, 1 knot (9.4 against 13.5 N): in the means only, the two
    intervals overlap (A up to 10.5 N, B down to 10.5 N) on the quick channel; the concentration and speed trends
    need the slow whole sweep (test_quick_sweep_trends)."""
    a, b = quick_case("A-c68-v1.0"), quick_case("B-c68-v1.0")
    assert b.mean_force_N > a.mean_force_N
