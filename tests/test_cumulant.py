"""D3Q27 cumulant collision (Geier et al. 2015): conservation, exact relaxation of the second-order
cumulants, lbmpy peer check, CPU = CUDA, float32 conditioning."""

import warnings

import numpy as np
import pytest
from numba import cuda

from iceresist import lattice as L
from iceresist.backends import jit
from iceresist.backends.jit import real_type
from iceresist.lbm.collide import build_collide_bgk
from iceresist.lbm.cumulant import build_collide_cumulant, flop_count
from iceresist.lbm.operators import get_collide_builder

_CACHE = {}


def _collide(target, real, omega_bulk=1.0, omega_higher=1.0):
    key = (target.name, real, omega_bulk, omega_higher)
    if key not in _CACHE:
        _CACHE[key] = build_collide_cumulant(target, real, omega_bulk=omega_bulk, omega_higher=omega_higher)
    return _CACHE[key]


def _run_cpu(f, omega, F, real=np.float64, omega_bulk=1.0, omega_higher=1.0):
    col = _collide(jit.cpu, real, omega_bulk, omega_higher)
    return np.array(col(tuple(real(v) for v in f), real(omega), *(real(v) for v in F)), dtype=np.float64)


def _near_equilibrium(rng, rho=1.02, u=(0.04, -0.03, 0.02), noise=0.01):
    """Deviations f - w of a perturbed equilibrium (non-equilibrium parts of relative size ``noise``)."""
    return L.equilibrium(rho, *u) * (1 + noise * rng.standard_normal(27)) - L.W


def _central_second(fdev, F):
    """rho, u (half-force shift) and the central second moments kappa_ab about u of f = fdev + w."""
    f = fdev + L.W
    rho = f.sum()
    u = (L.C.T @ f + 0.5 * np.asarray(F)) / rho
    d = L.C - u
    return rho, u, np.einsum("q,qa,qb->ab", f, d, d)


F_TEST = np.array([1e-4, -2e-4, 3e-5])


@pytest.mark.parametrize("precision", ["float64", "float32"])
def test_mass_conserved_and_momentum_gains_force(target, precision, rng):
    real = real_type(precision)
    f = _near_equilibrium(rng)
    if target.is_cuda:
        out = _run_cuda(target, real, f[None, :], 1.4, F_TEST)[0]
    else:
        out = _run_cpu(f, 1.4, F_TEST, real)
    f32 = f.astype(real).astype(np.float64)
    tol = 1e-6 if precision == "float32" else 1e-14
    assert abs(out.sum() - f32.sum()) < tol
    assert np.allclose(L.C.T @ out - L.C.T @ f32, F_TEST, rtol=0, atol=tol)


@pytest.mark.parametrize("omega", [0.6, 1.0, 1.9])
def test_equilibrium_keeps_second_moments(omega):
    """A polynomial equilibrium (paper eq. 12) has the equilibrium second-order cumulants: its second
    moments survive any omega exactly; only the third- and higher-order truncation terms move, O(u^3)."""
    changes = []
    for scale in (1.0, 0.5):
        rho, u = 1.03, scale * np.array([0.05, -0.04, 0.03])
        feq = L.equilibrium(rho, *u)
        out = _run_cpu(feq - L.W, omega, (0, 0, 0), omega_bulk=1.3) + L.W
        assert abs(out.sum() - rho) < 1e-14
        assert np.allclose(L.C.T @ out, rho * u, rtol=0, atol=1e-15)
        second = np.einsum("q,qa,qb->ab", out, L.C, L.C)
        assert np.allclose(second, rho * (L.CS2 * np.eye(3) + np.outer(u, u)), rtol=0, atol=1e-15)
        changes.append(np.abs(out - feq).max())
    assert 1e-5 < changes[0] < 0.5 * 0.05 ** 3
    assert 7.0 < changes[0] / changes[1] < 9.0  # third order in u


def test_zero_velocity_equilibrium_is_fixed_point():
    out = _run_cpu(L.equilibrium(1.01, 0, 0, 0) - L.W, 1.7, (0, 0, 0), omega_bulk=1.2, omega_higher=1.5)
    assert np.allclose(out, L.equilibrium(1.01, 0, 0, 0) - L.W, rtol=0, atol=1e-16)


@pytest.mark.parametrize("omega, omega_bulk", [(0.7, 1.0), (1.85, 1.3)])
@pytest.mark.parametrize("force", [(0.0, 0.0, 0.0), tuple(F_TEST)])
def test_second_order_cumulants_relax_exactly(omega, omega_bulk, force, rng):
    """Shear (off-diagonal, deviatoric) central moments scale by 1 - omega, the trace's departure from rho
    by 1 - omega_bulk (Geier et al. 2015 eqs. 58-60 without the Galilean correction)."""
    f = _near_equilibrium(rng, noise=0.03)
    out = _run_cpu(f, omega, force, omega_bulk=omega_bulk, omega_higher=1.2)
    rho, u, k = _central_second(f, force)
    assert abs(out.sum() - f.sum()) < 1e-14
    # post-collision momentum is rho u + F/2, so the post u with a reversed shift equals u
    u_post = (L.C.T @ (out + L.W) - 0.5 * np.asarray(force)) / rho
    assert np.allclose(u_post, u, rtol=0, atol=1e-15)
    d = L.C - u
    k2 = np.einsum("q,qa,qb->ab", out + L.W, d, d)
    g = 1 - omega
    for a, b in [(0, 1), (0, 2), (1, 2)]:
        assert k[a, b] != 0
        assert k2[a, b] == pytest.approx(g * k[a, b], abs=1e-15)
    assert k2[0, 0] - k2[1, 1] == pytest.approx(g * (k[0, 0] - k[1, 1]), abs=1e-15)
    assert k2[0, 0] - k2[2, 2] == pytest.approx(g * (k[0, 0] - k[2, 2]), abs=1e-15)
    assert np.trace(k2) - rho == pytest.approx((1 - omega_bulk) * (np.trace(k) - rho), abs=1e-15)


def test_omega_one_all_rates_gives_first_order_reflection_only(rng):
    """With every rate 1 the third- and higher-order cumulants vanish after the collision."""
    f = _near_equilibrium(rng, noise=0.05)
    out = _run_cpu(f, 1.0, (0, 0, 0)) + L.W
    rho = out.sum()
    u = L.C.T @ out / rho
    d = L.C - u
    k = np.einsum("q,qa,qb->ab", out, d, d)
    assert np.allclose(k, rho * L.CS2 * np.eye(3), rtol=0, atol=1e-15)
    k111 = np.sum(out * d[:, 0] * d[:, 1] * d[:, 2])
    k210 = np.sum(out * d[:, 0] ** 2 * d[:, 1])
    assert abs(k111) < 1e-15 and abs(k210) < 1e-15


# --- peer check against lbmpy ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def lbmpy_rule():
    """lbmpy 2.0 D3Q27 cumulant, compressible, zero-centred storage, symbolic rates and force (~20 s)."""
    pytest.importorskip("lbmpy")
    import sympy as sp
    from lbmpy import LBMConfig, LBMOptimisation, Method, Stencil, create_lb_collision_rule
    from lbmpy.stencils import LBStencil

    forces = sp.symbols("Fx Fy Fz")
    rates = sp.symbols("omega omega_bulk omega_higher")
    cfg = LBMConfig(stencil=LBStencil(Stencil.D3Q27), method=Method.CUMULANT, compressible=True,
                    zero_centered=True, force=forces, relaxation_rates=[rates[0], rates[1]] + [rates[2]] * 8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the unsimplified rule keeps logarithms; evaluated at 30 digits here
        rule = create_lb_collision_rule(
            lbm_config=cfg, lbm_optimisation=LBMOptimisation(simplification=False, pre_simplification=False))
    perm = np.array([L.index_of(*c) for c in rule.method.stencil])  # lbmpy q -> our q

    def evaluate(fdev, F, omegas):
        vals = {s: sp.Float(v, 30) for s, v in zip(rule.method.pre_collision_pdf_symbols, fdev[perm])}
        vals.update({s: sp.Float(v, 30) for s, v in zip(forces, F)})
        vals.update({s: sp.Float(v, 30) for s, v in zip(rates, omegas)})
        for a in rule.subexpressions:
            vals[a.lhs] = a.rhs.xreplace(vals).evalf(30)
        out = np.empty(27)
        out[perm] = [float(a.rhs.xreplace(vals).evalf(30)) for a in rule.main_assignments]
        return out

    return evaluate


@pytest.mark.parametrize("force", [(0.0, 0.0, 0.0), tuple(F_TEST)])
@pytest.mark.parametrize("omegas", [(1.3, 1.0, 1.0), (1.75, 1.2, 1.4)])
def test_matches_lbmpy_cumulant(lbmpy_rule, force, omegas, rng):
    """Same polynomial cumulant groups and central-moment forcing as lbmpy: agreement to round-off."""
    f = _near_equilibrium(rng, noise=0.02)
    ours = _run_cpu(f, omegas[0], force, omega_bulk=omegas[1], omega_higher=omegas[2])
    ref = lbmpy_rule(f, force, omegas)
    assert np.abs(ours - ref).max() < 1e-10
    assert np.abs(ours - f).max() > 1e-4  # the collision did something


# --- CUDA and float32 ----------------------------------------------------------------------------------

def _run_cuda(target, real, f_cells, omega, F):
    """Call the CUDA-compiled collision from a one-thread-per-cell kernel over ``f_cells`` (n, 27)."""
    col = _collide(target, real)
    o, fx, fy, fz = real(omega), real(F[0]), real(F[1]), real(F[2])

    @cuda.jit
    def kernel(fin, fout):
        i = cuda.grid(1)
        if i < fin.shape[0]:
            r = col((fin[i, 0], fin[i, 1], fin[i, 2], fin[i, 3], fin[i, 4], fin[i, 5], fin[i, 6], fin[i, 7],
                     fin[i, 8], fin[i, 9], fin[i, 10], fin[i, 11], fin[i, 12], fin[i, 13], fin[i, 14],
                     fin[i, 15], fin[i, 16], fin[i, 17], fin[i, 18], fin[i, 19], fin[i, 20], fin[i, 21],
                     fin[i, 22], fin[i, 23], fin[i, 24], fin[i, 25], fin[i, 26]), o, fx, fy, fz)
            for q in range(27):
                fout[i, q] = r[q]

    fin = np.ascontiguousarray(f_cells, dtype=real)
    fout = np.zeros_like(fin)
    kernel[1, 32](fin, fout)
    return fout.astype(np.float64)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_cuda_equals_cpu(precision, rng):
    if not jit.cuda_available():
        pytest.skip("no CUDA GPU and the simulator is off")
    target = jit.cuda()
    real = real_type(precision)
    cells = np.array([_near_equilibrium(rng, rho=1 + 0.01 * k, u=0.05 * rng.standard_normal(3)) for k in range(3)])
    gpu = _run_cuda(target, real, cells, 1.6, F_TEST)
    cpu = np.array([_run_cpu(c.astype(real), 1.6, F_TEST, real) for c in cells])
    tol = 2e-8 if precision == "float32" else 1e-16
    assert np.abs(gpu - cpu).max() < tol


def test_float32_is_well_conditioned(rng):
    """rho = 1 + 1e-4 perturbations: float32 f - w agrees with float64 to a few 1e-8 absolute (no O(1) cancels)."""
    worst = 0.0
    for _ in range(20):
        f = _near_equilibrium(rng, rho=1 + 1e-4 * rng.standard_normal(), u=0.05 * rng.standard_normal(3),
                              noise=1e-3)
        f32 = f.astype(np.float32).astype(np.float64)
        ref = _run_cpu(f32, 1.95, F_TEST, np.float64)
        out = _run_cpu(f32, 1.95, F_TEST, np.float32)
        worst = max(worst, np.abs(out - ref).max())
    assert worst < 5e-8  # measured 1.6e-8 over 200 cells (BGK: 1.3e-8)


def test_registry_and_rates_validation():
    assert get_collide_builder("cumulant") is build_collide_cumulant
    assert get_collide_builder("bgk") is build_collide_bgk
    with pytest.raises(ValueError, match="collision operator"):
        get_collide_builder("mrt")
    with pytest.raises(ValueError, match="omega_bulk"):
        build_collide_cumulant(jit.cpu, np.float64, omega_bulk=2.0)


def test_flop_count_is_pinned():
    """Live arithmetic operations per cell of the generated code (docs/PERFORMANCE.md)."""
    assert flop_count(1.0)["total"] == 740
    assert flop_count(1.4)["total"] == 1124
    assert flop_count(1.0)["div"] == 1
