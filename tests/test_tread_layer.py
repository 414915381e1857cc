"""Loaded modes with an incompressible tread layer in the patch (docs/physics.md §6 ground_contact, the tread
layer): limits, and a second discretisation of the ring with contact (finite differences of the rib's pressure
problem on the patch, a different harmonic basis) written here."""

import dataclasses
import math

import jax
import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
import scipy.sparse.linalg

from ringfit.params import table9
from ringfit.physics.loaded import layer_softening, loaded_natural_frequencies, patch_overlap, tread_layer_overlap
from ringfit.physics.natural import modal_stiffness, ring_modal_mass

A_4KN = math.radians(11.69)  # the seed tyre's computed half-angle at 4 kN (docs/physics.md §7)

# compiled once (eager op-by-op dispatch of the sine series is slow)
_loaded = jax.jit(loaded_natural_frequencies, static_argnums=(3,))
_layer = jax.jit(tread_layer_overlap, static_argnums=(3, 4))


def test_softening_law_limits_and_series():
    s = np.array([0.0, 1e-3, 0.049999, 0.050001, 0.5, 2.0, 50.0])
    g = np.asarray(layer_softening(s))
    assert g[0] == 1.0
    # closed form 3(1 − tanh s/s)/s² where it does not cancel; the series joins it continuously
    assert g[2] == pytest.approx(g[3], rel=2e-7)  # g′ = −0.04 there: 2e-6 apart in s
    assert g[4] == pytest.approx(3 * (1 - math.tanh(0.5) / 0.5) / 0.25, rel=1e-12)
    assert g[6] == pytest.approx(3 / 50.0**2 * (1 - 1 / 50.0), rel=1e-9)  # short waves: 3/s² (a thin rib flows)
    assert np.all(np.diff(g) <= 0)


@pytest.mark.slow  # two compilations of the patch block: ~10 s on a free core
def test_zero_rib_width_is_the_winkler_patch_and_narrow_ribs_tend_to_it():
    from ringfit.physics.loaded import loaded_matrices

    g, r = table9()
    assert float(g.tread_rib_width) == 0.0
    cc, ss = (np.asarray(x) for x in patch_overlap(A_4KN, 12))
    # B = 0 (traced, so the layer is computed and not selected) is the Winkler patch
    _, kc, ks = jax.jit(loaded_matrices, static_argnums=(3,))(r, g, A_4KN, 12)
    stiff = np.asarray(loaded_matrices(r, g, 0.0, 12)[1])
    np.testing.assert_allclose(np.asarray(kc), stiff + r.k_tread * g.radius * cc, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(ks), stiff + r.k_tread * g.radius * ss, rtol=1e-13)
    # Parseval: as B → 0 every sine mode of the patch keeps k_trd; what is left is the sine series' truncation
    # (0.15–0.3 % of the largest entry with 256 sines)
    lc, ls = (np.asarray(x) for x in _layer(A_4KN, g.radius, 1e-7, 12, 256))
    assert np.max(np.abs(lc - cc)) < 4e-3 * np.max(np.abs(cc))
    assert np.max(np.abs(ls - ss)) < 4e-3 * np.max(np.abs(ss))
    zero = _layer(0.0, g.radius, 0.05, 12, 256)
    assert np.all(np.asarray(zero[0]) == 0.0) and np.all(np.asarray(zero[1]) == 0.0)


def _fd_loaded(ring, geometry, a, rib, n_max=60, nx=240, ny=40):
    """Independent discretisation: the rib's pressure −∇²p = (12 k_trd/B³) w(x) on the patch rectangle
    [−L/2, L/2] × [−B/2, B/2] (p = 0 on its edges) by 5-point finite differences, the force per unit length
    ∫p dy and the stiffness ∫Φ_i f_j dx by the trapezoidal rule, the ring in n_max harmonics (not the package's
    40), one dense symmetric eigenproblem per parity. Returns the cos- and sin-type frequencies [Hz]."""
    R, kt = geometry.radius, ring.k_tread
    L = 2 * a * R
    hx, hy = L / nx, rib / ny
    x = -L / 2 + hx * np.arange(1, nx)
    n = np.arange(1, n_max + 1)

    def lap(m, h):
        return scipy.sparse.diags([np.full(m - 2, -1.0), np.full(m - 1, 2.0), np.full(m - 2, -1.0)], [-1, 0, 1]) / h**2

    A = (scipy.sparse.kron(lap(nx, hx), scipy.sparse.eye(ny - 1)) + scipy.sparse.kron(scipy.sparse.eye(nx - 1),
                                                                                     lap(ny, hy))).tocsc()
    solve = scipy.sparse.linalg.factorized(A)
    mass = np.asarray(ring_modal_mass(ring, geometry, n.astype(float)))
    stiff = np.asarray(np.pi * R * modal_stiffness(ring, geometry, n.astype(float)) / n**2)
    out = []
    for shape in (np.cos, np.sin):
        phi = shape(np.outer(n, x) / R)  # (N, nx−1)
        f = np.empty_like(phi)
        for i in range(n_max):
            p = solve(np.repeat(phi[i], ny - 1) * 12 * kt / rib**3).reshape(nx - 1, ny - 1)
            f[i] = p.sum(1) * hy  # ∫p dy (p = 0 at the sides)
        K = np.diag(stiff) + (phi * hx) @ f.T
        K = 0.5 * (K + K.T)
        out.append(np.sqrt(scipy.linalg.eigh(K, np.diag(mass), eigvals_only=True)) / (2 * np.pi))
    return out


@pytest.mark.slow  # the first compilation of the layered loaded model: ~10 s on a free core
@pytest.mark.parametrize("rib", [0.152, 0.03])
def test_tread_layer_matches_a_finite_difference_patch(rib):
    """The package's sine-series patch against the finite-difference one: the frequency rise over the free ring
    of n = 1…9 agrees to 2 % (and to 0.15 Hz), while it differs from the Winkler patch's rise by more at high n."""
    g, r = table9()
    gb = dataclasses.replace(g, tread_rib_width=rib)  # a static field
    c, s = (np.asarray(v)[:9] for v in _loaded(r, gb, A_4KN, 40))
    fc, fs = (v[:9] for v in _fd_loaded(r, g, A_4KN, rib))
    cw, sw = (np.asarray(v)[:9] for v in _loaded(r, g, A_4KN, 40))
    free = np.asarray(_loaded(r, g, 0.0, 40)[0])[:9]
    for model, fd, winkler in ((c, fc, cw), (s, fs, sw)):
        np.testing.assert_allclose(model - free, fd - free, rtol=0.02, atol=0.15)
        assert np.all(model <= winkler + 1e-9)
    # the layer's softening grows with n (the point of the model): n = 9 loses more than n = 2
    assert (cw - c)[8] > 3 * (cw - c)[1] > 0
