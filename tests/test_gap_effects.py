"""Every effect at its null gives back the baseline exactly; effects match independent formulas off the null."""

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.gap import effects as lib
from ringfit.gap.modal_rows import ModalRows
from ringfit.params import table9
from ringfit.physics.natural import (extensible_natural_frequencies, natural_angular_frequencies,
                                     rotating_natural_frequencies)


def _modal_rows(n, patch_deg=0.0, **kw):
    """ModalRows of one table (index 0) with the given columns; the rest at free-table defaults."""
    n = jnp.asarray(n, dtype=jnp.float64)
    m = n.shape[0]
    cols = dict(is_freq=jnp.ones(m), contact=jnp.zeros(m, dtype=jnp.int32), spin=jnp.zeros(m), branch=jnp.zeros(m),
                fixed_frame=jnp.zeros(m), cavity_hz=jnp.asarray(218.75), reference=jnp.ones(m),
                freq_hz=jnp.full(m, 150.0), table=jnp.zeros(m, dtype=jnp.int32),
                table_patch=jnp.asarray([math.radians(patch_deg)]))
    cols.update({k: jnp.asarray(v) for k, v in kw.items()})
    cols.setdefault("patch", jnp.where(cols["contact"] > 0, math.radians(patch_deg), 0.0))
    return ModalRows(n=n, **cols)


def _rows():
    n = np.array([0, 1, 2, 3, 5, 8, 2, 3, 2, 4, 3, 6, 2], float)
    return _modal_rows(
        n, patch_deg=11.69, is_freq=[1.0] * 12 + [0.0],
        contact=jnp.asarray([0, 0, 0, 0, 0, 0, 1, 2, 0, 0, 0, 0, 0], dtype=jnp.int32),
        spin=[0.0] * 8 + [40.0, 40.0, 40.0, 40.0, 0.0], branch=[0.0] * 8 + [1.0, -1.0, 1.0, -1.0, 0.0],
        fixed_frame=[0.0] * 10 + [1.0, 1.0, 0.0])


def test_registry_has_every_data_md_name():
    names = set(lib.available())
    assert set(lib.BUILTIN) <= names
    for name in lib.BUILTIN:
        e = lib.get(name)
        for p in e.params_for("modes") + e.params_for("profiles"):
            assert p.lo <= p.null <= p.hi and p.start != p.null


@pytest.mark.parametrize("name", lib.BUILTIN)
def test_null_is_baseline_exactly_modal(name):
    g, r = table9()
    rows = _rows()
    e = lib.get(name)
    omega = natural_angular_frequencies(r, g, rows.n)
    zeta = jnp.full_like(omega, 0.025)
    null = jnp.asarray([p.null for p in e.params_for("modes")])
    o2, z2 = e.modal(null, omega, zeta, rows, r, g)
    assert np.array_equal(np.asarray(o2), np.asarray(omega))
    assert np.array_equal(np.asarray(z2), np.asarray(zeta))


def test_rotation_matches_eq25_eq26():
    g, r = table9()
    rows = _rows()
    e = lib.get("rotation")
    omega = natural_angular_frequencies(r, g, rows.n)
    o2, _ = e.modal(jnp.asarray([1.0]), omega, jnp.zeros_like(omega), rows, r, g)
    f = np.asarray(o2) / (2 * math.pi)
    ref = np.asarray(rotating_natural_frequencies(r, g, jnp.asarray([2.0, 4.0]), 40.0))
    assert f[8] == pytest.approx(ref[0, 0], rel=1e-12)  # co-rotating backward n=2
    assert f[9] == pytest.approx(-ref[1, 1], rel=1e-12)  # co-rotating forward n=4
    # docs/physics.md §7: Ω = 43.95, n = 2, fixed frame backward 111.74 Hz
    rows2 = _modal_rows([2.0, 5.0], spin=jnp.full(2, 43.95), branch=jnp.ones(2), fixed_frame=jnp.ones(2))
    o3, _ = e.modal(jnp.asarray([1.0]), natural_angular_frequencies(r, g, rows2.n), jnp.zeros(2), rows2, r, g)
    np.testing.assert_allclose(np.asarray(o3) / (2 * math.pi), [111.74, 162.71], atol=0.01)


def test_extensibility_matches_2x2_eigenproblem():
    g, r = table9()
    rows = _rows()
    e = lib.get("ring_extensibility")
    ea = 2e4
    omega = natural_angular_frequencies(r, g, rows.n)
    o2, _ = e.modal(jnp.asarray([1e6 / ea]), omega, jnp.zeros_like(omega), rows, r, g)
    ref = np.asarray(extensible_natural_frequencies(r.replace(ea=ea), g, rows.n))[:, 0]
    np.testing.assert_allclose(np.asarray(o2)[1:6] / (2 * math.pi), ref[1:6], rtol=1e-9)


def test_sensor_mass_rayleigh_and_cavity_veering():
    g, r = table9()
    rows = _rows()
    omega = natural_angular_frequencies(r, g, rows.n)
    # sensor_mass acts on test tables only: the reference rows (all of _rows()) are left alone ...
    o1, _ = lib.get("sensor_mass").modal(jnp.asarray([0.003]), omega, jnp.zeros_like(omega), rows, r, g)
    np.testing.assert_array_equal(np.asarray(o1), np.asarray(omega))
    # ... and a test row is lowered by the Rayleigh factor
    test_rows = dataclasses.replace(rows, reference=jnp.zeros_like(rows.reference))
    o2, _ = lib.get("sensor_mass").modal(jnp.asarray([0.003]), omega, jnp.zeros_like(omega), test_rows, r, g)
    rel = np.asarray(o2)[3] / np.asarray(omega)[3] - 1.0  # n = 3
    expect = -0.003 / (2 * math.pi * g.radius * r.rho_a * (1 + 1 / 9))  # docs/physics.md §6, first order
    assert rel == pytest.approx(expect, rel=0.01)
    assert not lib.get("sensor_mass").modal_mask(rows).any() and lib.get("sensor_mass").modal_mask(test_rows)[:12].all()
    # cavity: 2-dof pencil solved with numpy.roots (independent form) for n = 1
    o3, _ = lib.get("cavity_mode").modal(jnp.asarray([1 / 0.015]), omega, jnp.zeros_like(omega), rows, r, g)
    m = 2 * r.rho_a
    rho0 = 1.2 * (g.pressure + 101325.0) / 101325.0
    kappa = g.width**2 * rho0 * 343.0**2 / 0.015
    ks, wa = m * float(omega[1]) ** 2, 2 * math.pi * 218.75
    x = np.sort(np.roots([m, -(ks + m * wa**2 + kappa), ks * wa**2]).real)
    assert float(o3[1]) == pytest.approx(math.sqrt(x[0]), rel=1e-10)


def test_ground_contact_computed_patch_gives_the_loaded_modes():
    """docs/physics.md §7: with a = 11.69° the loaded tyre's cos-type modes are 110.8, 128.9, 153.2 Hz and its
    sin-type ones 107.2, 121.1, 142.8 Hz (n = 1…3); a patch scale of 1 on that patch reproduces them."""
    g, r = table9()
    rows = _modal_rows([1.0, 2.0, 3.0, 1.0, 2.0, 3.0], patch_deg=11.69,
                       contact=jnp.asarray([1, 1, 1, 2, 2, 2], dtype=jnp.int32))
    e = lib.get("ground_contact")
    omega = natural_angular_frequencies(r, g, rows.n)
    o2, _ = e.modal(jnp.asarray([1.0]), omega, jnp.zeros_like(omega), rows, r, g)
    np.testing.assert_allclose(np.asarray(o2) / (2 * math.pi), [110.8, 128.9, 153.2, 107.2, 121.1, 142.8], atol=0.1)
    half, _ = e.modal(jnp.asarray([0.5]), omega, jnp.zeros_like(omega), rows, r, g)
    assert np.all(np.asarray(half) < np.asarray(o2)) and np.all(np.asarray(half) > np.asarray(omega))
