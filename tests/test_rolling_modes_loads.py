"""The model of the rolling, loaded tyre's modes against an independent discretisation, 0.05–1.2 × rated load
(docs/physics.md §3.7; issue 31 item 6).

The model (:func:`ringfit.physics.rolling_modes.loaded_rolling_modes`, the one behind ``ringfit campbell``,
``cleat --ssi`` labelling, the diagnosis's rolling rows and the synthetic cleat field) is Hill's method:
Fourier harmonics of the ring with the analytic Fourier coefficients of the tread springs on the patch.
The check (benchmarks/_independent_rolling.py, shared with the benchmark's independent rolling families) is
written from the PDEs alone: eq. (3.1) in the space-fixed angle α = θ + Ωt
(∂/∂t|θ = ∂/∂t + Ω∂/∂α), inextensible ring (w = −v′, the tension eliminated by virtual work), discretised
by **Fourier collocation** on an odd grid (a dense differentiation matrix, not harmonics), the contact
**sampled in space** (k_trd times the share of each grid cell inside the patch), and the quadratic
eigenproblem solved by a companion linearisation with a general (non-Hermitian) eigensolver. Only the
patch edges are taken from the steady rolling solution (§4, tested on its own); they are what the
contact *is* at that load.

Besides the frequencies, the collocation's eigenvectors give each mode's radial acceleration content
per harmonic (the content an accelerometer's data carry): the dominant signed harmonic, i.e. the order
and direction the model's Campbell labels report, is pinned too.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from ringfit.params import table9
from ringfit.physics.contact import patch_edges
from ringfit.physics.operating import Drum, OperatingPoint
from ringfit.physics.rolling_modes import loaded_rolling_modes, material_acceleration

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from _independent_rolling import collocation_modes  # noqa: E402

#: The Table 9 tyre's rated (nominal) load [N]: the thesis's drum tests and the examples run at 4 kN.
RATED_N = 4000.0
LOAD_SHARES = (0.05, 0.3, 0.6, 1.0, 1.2)
DRUM_M = 1.2192
OMEGA = 35.69  # rad/s: 40 km/h at R_e ≈ 0.3113 m
POINTS = 401  # odd: the collocation derivative is exact for orders ≤ 200
BAND_HZ = (100.0, 320.0)
#: frequency tolerance [Hz]: the model (K = 32) and the collocation at 401 points differ by ≤ 0.023 Hz at
#: 0.05 and 0.3 × rated (the collocation's own error, edges inside a cell: ≤ 0.07 Hz at 201 points)
TOL_HZ = 0.04


def _collocation_modes(ring, geometry, omega, leading, trailing, points=POINTS):
    """The shared independent collocation (benchmarks/_independent_rolling.py) on ringfit's parameter objects."""
    p = {k: float(getattr(ring, k)) for k in ("rho_a", "ei", "kw", "kv", "k_tread")}
    g = {"R": float(geometry.radius), "b": float(geometry.width), "p0": float(geometry.pressure)}
    return collocation_modes(p, g, omega, leading, trailing, chi=float(ring.chi), points=points)


@pytest.fixture(scope="module")
def tyre():
    return table9()


@pytest.mark.slow  # five loads, a contact solve and an 802 × 802 eigensolve each: ≈ 60 s
@pytest.mark.parametrize("share", LOAD_SHARES)
def test_loaded_rolling_modes_match_an_independent_collocation(tyre, share):
    g, r = tyre
    op = OperatingPoint(omega=OMEGA, load=share * RATED_N, road=Drum(diameter=DRUM_M))
    modes, sol = loaded_rolling_modes(r, g, op)
    assert bool(sol.ok)
    lead, trail = (float(x) for x in patch_edges(sol))
    f_model = np.asarray(modes.freq_hz)
    f_ref, k, acc = _collocation_modes(r, g, OMEGA, lead, trail)
    band = (f_ref > BAND_HZ[0]) & (f_ref < BAND_HZ[1])
    assert band.sum() >= 14
    # every mode of the band, one to one (both lists ascending)
    i0 = int(np.argmin(np.abs(f_model - f_ref[band][0])))
    np.testing.assert_allclose(f_model[i0:i0 + band.sum()], f_ref[band], atol=TOL_HZ, rtol=0)
    # the labels: dominant signed harmonic of the radial acceleration content, where it dominates clearly
    A, _ = material_acceleration(modes)
    A = np.abs(np.asarray(A)) ** 2
    A /= A.sum(axis=-1, keepdims=True)
    km = np.asarray(modes.k).astype(int)
    checked = 0
    for j, f in zip(np.flatnonzero(band), f_ref[band]):
        top = np.sort(acc[j])[::-1]
        if top[0] < top[1] + 0.1:  # a hybrid with two nearly equal harmonics: no clear label to pin
            continue
        i = int(np.argmin(np.abs(f_model - f)))
        if np.sum(np.abs(np.asarray(modes.radial)[i]) ** 2) < 1e-6:  # n = 0, the belt turning: no radial content
            continue
        assert km[np.argmax(A[i])] == k[np.argmax(acc[j])], (share, f)
        assert abs(A[i].max() - acc[j].max()) < 0.02, (share, f)
        checked += 1
    assert checked >= 8


def test_collocation_without_contact_is_eq26(tyre):
    """The check's own check (fast): no patch → the free spinning ring's fixed-frame eq. 26, closed form."""
    g, r = tyre
    f_ref, _, _ = _collocation_modes(r, g, OMEGA, 0.0, 0.0, points=61)
    R = float(g.radius)
    n = np.arange(2, 9, dtype=float)
    d = float(r.ei) * (n**2 - 1) ** 2 / R**4 + float(g.hoop_pressure_stiffness) * (n**2 - 1) + float(r.kw) \
        + float(r.kv) / n**2
    wf = np.sqrt(n**2 * d / (float(r.rho_a) * (n**2 + 1)))  # eq. 18
    root = np.sqrt(wf**2 + n**2 * (n**2 - 1) ** 2 * OMEGA**2 / (n**2 + 1) ** 2)
    shift = 2 * n * OMEGA / (n**2 + 1)
    fixed = np.abs(np.concatenate([shift + root, shift - root]) - np.concatenate([n, n]) * OMEGA) / (2 * np.pi)  # eq. 26
    for f in fixed:
        assert np.min(np.abs(f_ref - f)) < 1e-6 * f, f
