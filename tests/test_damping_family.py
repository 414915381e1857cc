"""The damping family's other forms (docs/physics.md §6): damping_growth (η ∝ n^b) and viscous_damping."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.gap import effects as lib
from ringfit.gap.modal_rows import ModalRows
from ringfit.params import table9


def _damping_rows(n, freq):
    m = len(n)
    return ModalRows(n=jnp.asarray(n, dtype=jnp.float64), is_freq=jnp.zeros(m), contact=jnp.zeros(m, dtype=jnp.int32),
                     spin=jnp.zeros(m), branch=jnp.zeros(m), fixed_frame=jnp.zeros(m), cavity_hz=jnp.asarray(218.75),
                     reference=jnp.ones(m), patch=jnp.zeros(m), freq_hz=jnp.asarray(freq),
                     table=jnp.zeros(m, dtype=jnp.int32), table_patch=jnp.zeros(1))


def test_growth_reaches_tenfold_over_n_1_to_9_inside_its_bounds():
    g, r = table9()
    n = np.arange(1.0, 10.0)
    rows = _damping_rows(n, 100.0 + 25.0 * n)
    e = lib.get("damping_growth")
    b = math.log(10.0) / math.log(9.0)  # ×10 from n = 1 to 9
    p = e.parameters[0]
    assert p.lo < b < p.hi  # a steep law is inside the bound (wave_damping's slope bound would cut it)
    zeta0 = jnp.full(n.size, 0.01)
    _, z = e.modal(jnp.asarray([b]), 2 * np.pi * rows.freq_hz, zeta0, rows, r, g)
    z = np.asarray(z)
    assert z[-1] / z[0] == pytest.approx(10.0, rel=1e-12)
    # ln ζ is linear in ln n (what makes b identifiable from three rows)
    np.testing.assert_allclose(np.diff(np.log(z)) / np.diff(np.log(n)), b, rtol=1e-12)
    # rows without n are left alone
    rows2 = _damping_rows([-1.0, 0.0], [100.0, 100.0])
    _, z2 = e.modal(jnp.asarray([b]), jnp.asarray([600.0, 600.0]), jnp.full(2, 0.01), rows2, r, g)
    assert np.array_equal(np.asarray(z2), np.full(2, 0.01))


def test_viscous_matches_its_closed_form():
    g, r = table9()
    rows = _damping_rows([1.0, 4.0], [107.0, 165.0])
    w = 2 * np.pi * np.asarray([107.0, 165.0])
    _, z = lib.get("viscous_damping").modal(jnp.asarray([400.0]), jnp.asarray(w), jnp.full(2, 0.02), rows, r, g)
    np.testing.assert_allclose(np.asarray(z), 0.02 + 400.0 / (2 * r.rho_a * w), rtol=1e-12)
