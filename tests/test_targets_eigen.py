"""The order sweep's eigen path (small-Z Schur, selected eigenvectors, threads) against LAPACK dgeev."""

import numpy as np
import pytest
from scipy.linalg.lapack import dgeev

from ringfit.targets import eigen
from ringfit.targets.ssi import block_hankel, output_covariances, poles_from_svd, truncated_svd
from ringfit.targets.stabilization import mac, pair_basis, stabilization_diagram, subspace_mac

from test_targets_ssi import FS, _simulate


def _upper(wr, wi):
    return np.flatnonzero(wi > 0)


def _reference(g, c):
    """All eigenvalues and the shapes c·x of the upper pair members, from dgeev's full eigenvectors."""
    wr, wi, _, vr, info = dgeev(g, compute_vl=0, compute_vr=1)
    assert info == 0
    j = np.flatnonzero(wi > 0)
    return wr + 1j * wi, wr[j] + 1j * wi[j], c @ (vr[:, j] + 1j * vr[:, j + 1])


@pytest.mark.parametrize("n, l", [(3, 2), (40, 32), (150, 32), (20, 300), (230, 16)])
@pytest.mark.parametrize("direct", [True, False])
def test_eigenvalues_and_shapes_match_dgeev(monkeypatch, n, l, direct):
    """Every eigenvalue and every chosen shape agree with dgeev (n = 230 takes the dlaqr0 branch; l > n works)."""
    if not direct:
        monkeypatch.setattr(eigen, "direct_lapack_available", lambda: False)
    assert eigen.direct_lapack_available() is direct
    rng = np.random.default_rng(n + l)
    g = rng.standard_normal((n, n)) / np.sqrt(n)
    c = rng.standard_normal((l, n))
    g0, c0 = g.copy(), c.copy()
    wr, wi, j, phi = eigen.eig_shapes(g, c, _upper)
    assert np.array_equal(g, g0) and np.array_equal(c, c0)  # inputs untouched
    lam_all, lam_ref, phi_ref = _reference(g, c)
    assert np.allclose(np.sort_complex(wr + 1j * wi), np.sort_complex(lam_all), rtol=1e-10, atol=1e-12)
    assert np.array_equal(j, np.flatnonzero(wi > 0))
    assert phi.shape == (l, j.size)
    for k in range(j.size):
        i = np.argmin(np.abs(lam_ref - (wr[j[k]] + 1j * wi[j[k]])))
        assert mac(phi[:, k], phi_ref[:, i]) > 1 - 1e-10


def test_only_the_chosen_shapes_are_computed():
    rng = np.random.default_rng(3)
    g, c = rng.standard_normal((60, 60)), rng.standard_normal((5, 60))
    wr, wi, j, phi = eigen.eig_shapes(g, c, lambda wr, wi: np.flatnonzero(wi > 0)[::-3])  # unsorted choice
    assert np.all(np.diff(j) > 0) and phi.shape == (5, j.size)
    _, lam_ref, phi_ref = _reference(g, c)
    for k in range(j.size):
        i = np.argmin(np.abs(lam_ref - (wr[j[k]] + 1j * wi[j[k]])))
        assert mac(phi[:, k], phi_ref[:, i]) > 1 - 1e-10
    none = eigen.eig_shapes(g, c, lambda wr, wi: np.zeros(0, int))
    assert none[2].size == 0 and none[3].shape == (5, 0)


@pytest.fixture(scope="module")
def svd_of_simulation():
    y = _simulate(n_out=6, n_samples=30_000, seed=11)
    p = 12
    u, s, _ = np.linalg.svd(block_hankel(output_covariances(y, 2 * p - 1), p))
    return y, u, s


def test_threads_do_not_change_the_poles(svd_of_simulation):
    _, u, s = svd_of_simulation
    orders = range(2, 61, 2)
    one = poles_from_svd(u, s, 6, orders, 1 / FS, workers=1)
    three = poles_from_svd(u, s, 6, orders, 1 / FS, workers=3)
    for name in ("order", "lam", "shape"):
        assert np.array_equal(getattr(one, name), getattr(three, name))


def test_threaded_svd_products_agree(svd_of_simulation):
    y, _, _ = svd_of_simulation
    h = block_hankel(output_covariances(y, 23), 12)
    u1, s1 = truncated_svd(h, 40, workers=1)
    u2, s2 = truncated_svd(h, 40, workers=2)
    assert np.allclose(s1, s2, rtol=1e-10)
    top = s1 > 1e-3 * s1[0]  # well-separated triplets: same vectors up to sign
    assert np.allclose(np.abs(np.sum(u1[:, top] * u2[:, top], axis=0)), 1.0, atol=1e-8)


def test_pair_mac_is_evaluated_exactly_where_it_decides_the_label(svd_of_simulation):
    """Labels against a per-pole evaluation of the pair MAC for EVERY frequency-stable pole (pair_basis + subspace_mac)."""
    _, u, s = svd_of_simulation
    poles = poles_from_svd(u, s, 6, range(2, 61, 2), 1 / FS)
    window, history, tol = 0.02, 3, 0.9
    st = stabilization_diagram(poles, pair_window=window, history=history, mac_tol=tol)
    f, phi = poles.freq_hz, poles.shape
    by_order = [poles.at_order(o) for o in poles.orders]
    reference = np.zeros(len(poles), bool)
    for j in range(1, len(by_order)):
        hist = np.concatenate(by_order[max(0, j - history):j])
        for i in by_order[j]:
            if not st.freq[i]:
                continue
            near = hist[np.abs(f[hist] - f[i]) <= window * f[i]]
            pair = subspace_mac(pair_basis(phi[near]), phi[i])[0] if near.size else 0.0
            reference[i] = st.plain_mac[i] >= tol or pair >= tol
            if np.isfinite(st.pair_mac[i]):
                assert st.pair_mac[i] == pytest.approx(pair, abs=1e-9)
    assert np.array_equal(st.shape & st.freq, reference)
    evaluated = np.isfinite(st.pair_mac)
    assert np.array_equal(evaluated, st.freq & (st.plain_mac < tol))


def test_a_qr_iteration_that_does_not_converge_falls_back_to_dgeev(monkeypatch):
    """dlahqr reporting non-convergence (info > 0) sends that matrix through dgeev: same eigenvalues and shapes."""
    real = eigen._lapack

    def failing(name):
        if name != "dlahqr":
            return real(name)

        def dlahqr(*args):
            args[-1]._obj.value = 1  # INFO: eigenvalue 1 did not converge

        return dlahqr

    monkeypatch.setattr(eigen, "_lapack", failing)
    rng = np.random.default_rng(9)
    g, c = rng.standard_normal((30, 30)), rng.standard_normal((4, 30))
    wr, wi, j, phi = eigen.eig_shapes(g, c, _upper)
    lam_all, lam_ref, phi_ref = _reference(g, c)
    assert np.allclose(np.sort_complex(wr + 1j * wi), np.sort_complex(lam_all), rtol=1e-12)
    for k in range(j.size):
        i = np.argmin(np.abs(lam_ref - (wr[j[k]] + 1j * wi[j[k]])))
        assert mac(phi[:, k], phi_ref[:, i]) > 1 - 1e-12
