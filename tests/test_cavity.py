"""The loaded cavity (docs/physics.md §6 cavity_mode, ringfit.physics.cavity): the contact flat splits the
first acoustic pair into a lower fore-aft and a higher vertical line."""

import math

import numpy as np
import pytest
import scipy.linalg

from ringfit.params import table9
from ringfit.physics.cavity import cavity_height, loaded_cavity_frequencies, loaded_cavity_lines
from ringfit.physics.natural import CAVITY_LENGTH, SOUND_SPEED

#: The seed tyre's load index 94 → 670 kg (ETRTO), its rated load.
RATED_N = 670.0 * 9.80665


def _webster_fd(area, nodes):
    """Independent check: Webster's equation (A p′)′ + (ω/c)² A p = 0 on a closed loop of length L_c by
    finite volumes (``nodes`` cells, faces between them carrying the mean area); returns ω² ascending."""
    L = CAVITY_LENGTH
    h = L / nodes
    a_face = 0.5 * (area + np.roll(area, -1))
    K = np.zeros((nodes, nodes))
    for i in range(nodes):
        j = (i + 1) % nodes
        k = a_face[i] / h**2
        K[i, i] += k
        K[j, j] += k
        K[i, j] -= k
        K[j, i] -= k
    return scipy.linalg.eigh(K, np.diag(area), eigvals_only=True) * SOUND_SPEED**2


def test_perturbation_matches_finite_volume_webster():
    """A small cos 2θ area change: the first-order lines against an independent finite-volume loop."""
    nodes = 720
    th = 2 * np.pi * np.arange(nodes) / nodes
    for eps in (0.01, -0.02):
        lam = _webster_fd(1.0 + eps * np.cos(2 * th), nodes)
        w_fd = np.sqrt(lam[1:3])  # the first pair (lam[0] = 0: uniform pressure)
        # the same discretisation without the perturbation, to remove its own dispersion error
        w0 = np.sqrt(_webster_fd(np.ones(nodes), nodes)[1])
        # ε = W_2/h_c: ∫ε cos 2θ dθ = π W_2/h_c
        fa, vt = loaded_cavity_lines(w0, eps)
        np.testing.assert_allclose(np.sort([float(fa), float(vt)]), np.sort(w_fd), rtol=abs(eps) ** 2 * 2)


def test_seed_tyre_direction_law_and_magnitude():
    g, r = table9()
    assert float(cavity_height(g)) == pytest.approx(2 * (0.296 - 1.568 / (2 * math.pi)), rel=1e-12)
    fa1, vt1, e1 = (float(x) for x in loaded_cavity_frequencies(r, g, RATED_N))
    fa2, vt2, e2 = (float(x) for x in loaded_cavity_frequencies(r, g, RATED_N / 2))
    f_a = SOUND_SPEED / CAVITY_LENGTH
    # direction: the flat lowers the fore-aft line and raises the vertical one
    assert fa1 < f_a < vt1 and fa2 < f_a < vt2
    split1, split2 = vt1 - fa1, vt2 - fa2
    # magnitude at the rated load: inside the published 4–14 Hz (Choi & Bolton, INTER-NOISE 2020)
    assert 4.0 < split1 < 14.0, split1
    # law: split ∝ W_2 (first order in the area change), and the ring's static W_2 is linear in the load up to
    # the patch's growth, so split(F)/split(F/2) = W_2(F)/W_2(F/2) ≈ 2, not the measured ≈ 4 (load²):
    # docs/physics.md §6 cavity_mode, "the load law", shows why (and test_load_law_is_first_order below
    # checks it against the exact Webster loop). The ratio is pinned to the contact solve's own W_2 ratio.
    assert split1 / split2 == pytest.approx(e1 / e2, rel=0.02)
    assert 1.8 < split1 / split2 < 2.3, split1 / split2
    # unloaded: no split
    fa0, vt0 = loaded_cavity_lines(2 * np.pi * f_a, 0.0)
    assert float(fa0) == float(vt0)


def test_rotation_splits_and_the_lines_stay_ordered():
    wa = 2 * np.pi * 218.75
    e = -0.04
    fa0, vt0 = loaded_cavity_lines(wa, e, 0.0)
    fa, vt = loaded_cavity_lines(wa, e, 50.0)
    assert float(fa) < float(fa0) < float(vt0) < float(vt)
    # at high speed the pair is the air's two travelling waves ω_a ± Ω
    fa, vt = loaded_cavity_lines(wa, e, 1e3)
    assert float(vt) - wa == pytest.approx(1e3, rel=1e-3) and wa - float(fa) == pytest.approx(1e3, rel=1e-3)


def test_cavity_mode_effect_uses_the_direction_lines_and_respects_no_air():
    import jax.numpy as jnp

    from ringfit.gap import effects as lib
    from ringfit.gap.modal_rows import ModalRows
    from ringfit.physics.natural import natural_angular_frequencies

    g, r = table9()
    f_a = 218.75
    e = -0.04
    cav = [f_a * math.sqrt(1 - e), f_a * math.sqrt(1 + e), 0.0]  # vert row, hort row, a table without air
    m = 3
    rows = ModalRows(n=jnp.ones(m), is_freq=jnp.ones(m), contact=jnp.asarray([1, 2, 1], dtype=jnp.int32),
                     spin=jnp.zeros(m), branch=jnp.zeros(m), fixed_frame=jnp.zeros(m), cavity_hz=jnp.asarray(cav),
                     reference=jnp.zeros(m), patch=jnp.zeros(m), freq_hz=jnp.full(m, 110.0),
                     table=jnp.zeros(m, dtype=jnp.int32), table_patch=jnp.zeros(1))
    eff = lib.get("cavity_mode")
    assert list(eff.modal_mask(rows)) == [True, True, False]
    omega = natural_angular_frequencies(r, g, rows.n)
    o, _ = eff.modal(jnp.asarray([1 / 0.015]), omega, jnp.zeros(m), rows, r, g)
    o = np.asarray(o)
    assert o[2] == float(omega[2])
    # the ring's n = 1 is below the air: a higher air line pulls it down less
    assert o[0] < float(omega[0]) and o[1] < o[0]


@pytest.mark.slow
def test_load_law_is_first_order():
    """The split's load law (docs/physics.md §6 cavity_mode, the load law). The exact loop — finite-volume
    Webster with the whole area change ε(θ) = w(θ)/h_c of the contact solve, not its cos 2θ part — gives the
    first-order split to 5 % at F and F/2, so their ratio is W_2(F)/W_2(F/2) ≈ 2. Everything beyond first order
    (the same loop with the cos 2θ part of ε removed: then only second-order terms can split the pair) is
    < 6 % of the split at the rated load: a section that kept its area to first order (the only way to a
    load² law here) would split by ~0.4 Hz at the rated load, 10–35 times below the published 4–14 Hz."""
    from ringfit.physics.cavity import deflection_cos2
    from ringfit.physics.contact import ContactSolver, solve_rolling_jit
    from ringfit.physics.operating import FlatRoad, OperatingPoint

    g, r = table9()
    hc = float(cavity_height(g))
    nodes = 1024
    w0 = math.sqrt(_webster_fd(np.ones(nodes), nodes)[1])
    exact, first, rest = [], [], []
    for load in (RATED_N, RATED_N / 2):
        sol = solve_rolling_jit(r, g, OperatingPoint(0.0, load, FlatRoad()), solver=ContactSolver(n_grid=nodes))
        phi, eps = np.asarray(sol.phi), np.asarray(sol.w) / hc
        e2 = float(deflection_cos2(sol)) / hc
        lam = np.sqrt(_webster_fd(1.0 + eps, nodes)[1:3])
        lam_rest = np.sqrt(_webster_fd(1.0 + eps - e2 * np.cos(2 * phi), nodes)[1:3])
        exact.append((lam[1] - lam[0]) / (2 * np.pi))
        rest.append((lam_rest[1] - lam_rest[0]) / (2 * np.pi))
        fa, vt = loaded_cavity_lines(w0, e2)
        first.append(float(vt - fa) / (2 * np.pi))
    np.testing.assert_allclose(exact, first, rtol=0.05)
    assert exact[0] / exact[1] == pytest.approx(first[0] / first[1], rel=0.03)
    assert 1.8 < exact[0] / exact[1] < 2.3
    assert rest[0] < 0.06 * exact[0]
