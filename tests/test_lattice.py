"""D3Q27 velocity set: isotropy conditions that every LBM derivation assumes."""

import numpy as np

from iceresist import lattice as L


def test_weights_and_isotropy():
    assert L.C.shape == (27, 3)
    assert np.isclose(L.W.sum(), 1.0, atol=1e-15)
    # second-order isotropy: sum w c_a c_b = cs^2 delta_ab
    m2 = np.einsum("q,qa,qb->ab", L.W, L.C, L.C)
    assert np.allclose(m2, L.CS2 * np.eye(3), atol=1e-15)
    # fourth-order isotropy: sum w c_a c_b c_c c_d = cs^4 (d_ab d_cd + d_ac d_bd + d_ad d_bc)
    m4 = np.einsum("q,qa,qb,qc,qd->abcd", L.W, L.C, L.C, L.C, L.C)
    d = np.eye(3)
    iso = L.CS2**2 * (np.einsum("ab,cd->abcd", d, d) + np.einsum("ac,bd->abcd", d, d) + np.einsum("ad,bc->abcd", d, d))
    assert np.allclose(m4, iso, atol=1e-15)


def test_opposites():
    assert np.array_equal(L.C[L.OPP], -L.C)
    assert L.OPP[0] == 0
    for q in range(1, 27):
        assert L.OPP[q] == (q + 1 if q % 2 else q - 1)


def test_equilibrium_moments():
    feq = L.equilibrium(1.1, 0.05, -0.02, 0.03)
    assert np.isclose(feq.sum(), 1.1)
    assert np.allclose(L.C.T @ feq, 1.1 * np.array([0.05, -0.02, 0.03]))
