"""Covariance SSI against a state-space system with known poles, and its building blocks."""

import numpy as np
import pytest

from ringfit.targets import ssi as ssi_module
from ringfit.targets.ssi import (BlockHankelOperator, block_hankel, output_covariances, poles_from_svd, ssi_cov,
                                 ssi_cov_multi_setup, truncated_svd)
from ringfit.targets.stabilization import mac, stabilization_diagram

FS = 200.0
#: (frequency Hz, damping ratio) of the test system: the independent truth.
TRUTH = [(11.0, 0.02), (23.0, 0.015), (37.0, 0.03)]


def _simulate(n_out=6, n_samples=100_000, seed=0, noise=0.02):
    """Sum of white-noise-driven second-order sections with exact discrete poles exp(λ dt), seen by n_out sensors."""
    from scipy.signal import lfilter

    rng = np.random.default_rng(seed)
    dt = 1 / FS
    y = np.zeros((n_out, n_samples))
    for f, z in TRUTH:
        lam = -z * 2 * np.pi * f + 1j * 2 * np.pi * f * np.sqrt(1 - z**2)
        mu = np.exp(lam * dt)
        s = lfilter([1.0], [1.0, -2 * mu.real, abs(mu) ** 2], rng.standard_normal(n_samples + 1))
        c = rng.standard_normal((n_out, 2))
        y += c[:, :1] * s[1:] + c[:, 1:] * s[:-1]
    y += noise * y.std() * rng.standard_normal(y.shape)
    return y


def test_covariances_match_direct_sums():
    rng = np.random.default_rng(1)
    y = rng.standard_normal((3, 50))
    cov = output_covariances(y, 5, refs=[0, 2])
    n = y.shape[1]
    for i in range(6):
        direct = sum(np.outer(y[:, k + i], y[[0, 2], k]) for k in range(n - i)) / (n - i)
        assert np.allclose(cov[i], direct, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("chunk_bytes", [None, 4096])
def test_fft_covariances_match_direct_sums(monkeypatch, chunk_bytes):
    """The blocked-FFT path (long records) against the defining sums, also when the blocks go in several chunks."""
    if chunk_bytes is not None:
        monkeypatch.setattr(ssi_module, "_FFT_COV_CHUNK_BYTES", chunk_bytes)
    rng = np.random.default_rng(5)
    y = rng.standard_normal((4, 4013)) + 3.0  # odd length, non-zero mean: ~84 blocks, the last ones zero-padded
    lags = 24  # >= 16 lags and n >= 8 * lags: the FFT path
    cov = output_covariances(y, lags - 1, refs=[3, 1])
    n = y.shape[1]
    for i in range(lags):
        direct = y[:, i:] @ y[[3, 1], : n - i].T / (n - i)
        assert np.allclose(cov[i], direct, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("p, q", [(5, 5), (4, 7)])
def test_block_hankel_operator_products(p, q):
    rng = np.random.default_rng(6)
    cov = rng.standard_normal((p + q + 2, 3, 2))
    dense = block_hankel(cov, p, q)
    op = BlockHankelOperator(cov, p, q)
    x, z = rng.standard_normal((q * 2, 4)), rng.standard_normal((p * 3, 5))
    assert op.shape == dense.shape
    assert np.allclose(op @ x, dense @ x, rtol=1e-13, atol=1e-13)
    assert np.allclose(op.T @ z, dense.T @ z, rtol=1e-13, atol=1e-13)
    assert np.array_equal(op.toarray(), dense)


def test_sweep_matches_least_squares_a_per_order():
    """Poles and shapes of every order against A_n = O↑_n⁺ O↓_n (eq. 11) solved independently per order."""
    y = _simulate(n_out=4, n_samples=20_000, seed=7)
    p, orders = 8, [2, 6, 10, 20]
    u, s, _ = np.linalg.svd(block_hankel(output_covariances(y, 2 * p - 1), p))
    poles = poles_from_svd(u, s, 4, orders, 1 / FS, max_damping=1.0)
    for n in orders:
        obs = u[:, :n] * np.sqrt(s[:n])
        a = np.linalg.lstsq(obs[:-4], obs[4:], rcond=None)[0]
        mu, psi = np.linalg.eig(a)
        lam = np.log(mu) / (1 / FS)
        zeta = -lam.real / np.abs(lam)
        keep = (mu.imag > 0) & (zeta > 0) & (zeta < 1.0)
        i = poles.at_order(n)
        assert i.size == keep.sum()
        ref = np.sort_complex(lam[keep])
        assert np.allclose(np.sort_complex(poles.lam[i]), ref, rtol=1e-9)
        phi_ref = (obs[:4] @ psi[:, keep]).T
        for j in i:  # each shape matches the reference shape of the same pole (MAC ~ 1)
            k = np.argmin(np.abs(lam[keep] - poles.lam[j]))
            assert mac(poles.shape[j], phi_ref[k]) > 1 - 1e-9


def test_many_channels_use_the_fft_hankel_and_agree_with_the_dense_path():
    """l·r >= FFT_HANKEL_MIN_LR: the operator path gives the poles of the full dense SVD."""
    y = _simulate(n_out=64, n_samples=6_000, seed=8)
    assert isinstance(ssi_module.hankel_for_svd(output_covariances(y, 9), 5), BlockHankelOperator)
    fast = ssi_cov(y, FS, orders=[6, 12], block_rows=5)
    full = ssi_cov(y, FS, orders=[6, 12], block_rows=5, svd_method="full")
    i, j = fast.at_order(6), full.at_order(6)
    assert np.allclose(np.sort(fast.freq_hz[i]), np.sort(full.freq_hz[j]), rtol=1e-9)
    assert np.allclose(np.sort(fast.freq_hz[i]), [t[0] for t in TRUTH], rtol=0.01)


def test_block_hankel_layout():
    cov = np.arange(8 * 2 * 1, dtype=float).reshape(8, 2, 1)  # Λ_i = [[2i], [2i+1]]
    h = block_hankel(cov, 3, 4)
    assert h.shape == (6, 4)
    for i in range(3):
        for j in range(4):
            assert np.array_equal(h[2 * i:2 * i + 2, j], cov[i + j + 1, :, 0])


@pytest.mark.parametrize("method", ["randomized", "svds"])
def test_truncated_svd_matches_full(method):
    rng = np.random.default_rng(2)
    u0, _ = np.linalg.qr(rng.standard_normal((300, 300)))
    s0 = np.concatenate([np.logspace(3, 0, 40), 1e-3 * rng.random(260)])
    h = (u0 * s0) @ np.linalg.qr(rng.standard_normal((300, 300)))[0].T
    u, s = truncated_svd(h, 30, method=method)
    assert np.allclose(s, s0[:30], rtol=1e-8)
    assert np.all(mac(u.T, u0[:, :30].T) > 1 - 1e-8)


def _recovered(poles, order):
    i = poles.at_order(order)
    return poles.freq_hz[i], poles.damping[i]


def test_ssi_recovers_known_poles():
    y = _simulate()
    poles = ssi_cov(y, FS, orders=range(2, 31, 2), block_rows=10)
    f, z = _recovered(poles, 6)  # the true order
    assert f.size == 3
    for (ft, zt), fi, zi in zip(TRUTH, np.sort(f), z[np.argsort(f)]):
        assert abs(fi - ft) / ft < 0.003  # ~2σ of the estimator for 500 s of data
        assert abs(zi - zt) / zt < 0.15
    stab = stabilization_diagram(poles)
    for ft, _ in TRUTH:  # each true pole is stable (square) at most orders above the true one
        near = (np.abs(poles.freq_hz - ft) < 0.01 * ft) & (poles.order >= 8)
        assert np.mean(stab.label[near] == 2) > 0.7


def test_multi_setup_matches_single_setup():
    """Two setups sharing reference channel 0: the merged Hankel gives the same poles as all channels at once."""
    y = _simulate(n_out=5, seed=3)
    setup1 = y[[0, 1, 2]]
    setup2 = 3.0 * y[[0, 3, 4]]  # another excitation level
    poles, channel_map = ssi_cov_multi_setup([setup1, setup2], [[0], [0]], FS, orders=[6], block_rows=12)
    assert channel_map == [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2)]
    f = np.sort(poles.freq_hz)
    assert np.allclose(f, [t[0] for t in TRUTH], rtol=0.005)
    # shapes: merged channels follow the single-setup shapes (MAC ~ 1)
    single = ssi_cov(y, FS, orders=[6], refs=[0], block_rows=12)
    for i in range(3):
        j = np.argmin(np.abs(single.freq_hz - poles.freq_hz[i]))
        assert mac(poles.shape[i], single.shape[j]) > 0.98


def test_bad_inputs():
    from ringfit.errors import InputError

    with pytest.raises(InputError, match="NaN"):
        ssi_cov(np.full((2, 100), np.nan), FS)
    with pytest.raises(InputError, match="block.rows"):
        ssi_cov(np.random.default_rng(0).standard_normal((2, 500)), FS, orders=[40], block_rows=12)
