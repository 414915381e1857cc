"""The independent finite-difference truth of the joint identification cases (ringfit.synth.independent, issue 32
item 4) pinned against closed forms written here from docs/physics.md — never against ringfit's own model."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from ringfit.params import table9
from ringfit.synth import independent as ind

GEOMETRY, RING = table9()


def extensible_flexural_hz(n: int, ea: float, kw_extra: float = 0.0) -> float:
    """docs/physics.md §2.2: the lower root of det(K_n − ρAω²I) = 0, written from the doc's matrix."""
    R, b, p0 = GEOMETRY.radius, GEOMETRY.width, GEOMETRY.pressure
    P, EI, kw, kv, rho = p0 * b / R, RING.ei, RING.kw + kw_extra, RING.kv, RING.rho_a
    K = np.array([[EI * n**4 / R**4 + ea / R**2 + kw + P * (n * n - 1), EI * n**3 / R**4 + ea * n / R**2],
                  [EI * n**3 / R**4 + ea * n / R**2, EI * n * n / R**4 + ea * n * n / R**2 + kv]])
    return math.sqrt(np.linalg.eigvalsh(K)[0] / rho) / (2 * math.pi)


def eq18_hz(n: int, kw_extra: float = 0.0) -> float:
    """docs/physics.md §2.1, eq. 18."""
    R, b, p0 = GEOMETRY.radius, GEOMETRY.width, GEOMETRY.pressure
    num = (RING.ei / R**4 * n**2 * (n**2 - 1) ** 2 + p0 * b / R * n**2 * (n**2 - 1)
           + (RING.kw + kw_extra) * n**2 + RING.kv)
    return math.sqrt(num / (RING.rho_a * (1 + n**2))) / (2 * math.pi)


@pytest.mark.parametrize("order, grids", [(2, (48, 96, 192)), (4, (32, 64, 128))])
def test_free_fd_frequencies_converge_to_the_closed_form_at_the_stencils_order(order, grids):
    """Halving h divides the error by 2^order (measured 2.00 and 3.9–4.0 at n = 2 … 6)."""
    ns = np.arange(2, 7)
    exact = np.array([extensible_flexural_hz(n, ind.EA_PENALTY) for n in ns])
    errs = [np.abs(ind.fd_free_frequencies(RING, GEOMETRY, 6, N, order=order)[1:] / exact - 1) for N in grids]
    for coarse, fine in zip(errs[:-1], errs[1:]):
        rate = np.log2(coarse / fine)
        assert np.all(np.abs(rate - order) < 0.15 * order), rate


def test_free_fd_frequencies_of_the_default_grid_are_eq18():
    """The penalty EA = 1e9 N and the default 4th-order grid: eq. 18 within 1e-6 for n = 1 … 9."""
    f = ind.fd_free_frequencies(RING, GEOMETRY, 9)
    np.testing.assert_allclose(f, [eq18_hz(n) for n in range(1, 10)], rtol=1e-6)


def test_a_patch_round_the_whole_ring_is_a_stiffer_radial_foundation():
    """Tread springs on every point (a = π) add k_trd to k_w: §2.2/eq. 18 with k_w + k_trd for every harmonic (modes
    without w — the rigid rotation, the central stencils' Nyquist tangential mode — left out)."""
    f, w, v = ind.fd_modes(RING, GEOMETRY, 256, half_angle=math.pi, count=20)
    got = {}
    for j in range(f.size):
        if np.linalg.norm(w[:, j]) > 1e-3 * np.linalg.norm(v[:, j]):
            got.setdefault(int(np.argmax(np.abs(np.fft.rfft(w[:, j])))), []).append(f[j])
    for n in range(1, 6):
        # §2.2's root at the penalty EA (k_w + k_trd = 20 MN/m² puts eq. 18 itself 2e-4 off at n = 1)
        np.testing.assert_allclose(got[n], extensible_flexural_hz(n, ind.EA_PENALTY, RING.k_tread), rtol=2e-5)
        assert got[n][0] == pytest.approx(eq18_hz(n, RING.k_tread), rel=3e-4)


@pytest.mark.parametrize("n", [2, 3, 5])
def test_a_short_soft_patch_shifts_the_modes_as_first_order_perturbation_says(n):
    """A patch |φ| < a of soft springs (k_trd/100, so that second order is ~1e-3 of the shift): the cosine-type
    mode w = cos nφ, v = −sin nφ/n gains δ(ω²) = k_trd ∫_{−a}^{a} w² / (ρA ∫ (w² + v²)) =
    k_trd (a + sin 2na/(2n)) / (ρA π (1 + 1/n²)); the sine-type mode, ∫ sin² nφ over the patch instead."""
    a = math.radians(2.0)
    soft = RING.replace(k_tread=RING.k_tread / 100)
    c, s = ind.fd_loaded_frequencies(soft, GEOMETRY, a, 6)
    f0 = ind.fd_free_frequencies(soft, GEOMETRY, 6)[n - 1]  # the same discretisation without the patch
    mass = soft.rho_a * math.pi * (1 + 1 / n**2)
    for got, integral in ((c[n - 1], a + math.sin(2 * n * a) / (2 * n)), (s[n - 1], a - math.sin(2 * n * a) / (2 * n))):
        shift = (2 * math.pi) ** 2 * (got**2 - f0**2)
        assert shift == pytest.approx(soft.k_tread * integral / mass, rel=0.02)


def test_channels_of_an_inextensible_harmonic_are_the_closed_form():
    """§4.6 inextensible: a_r,n = −Ω²(n²−1)W_n, a_θ,n = iΩ²(n²−1)W_n/n; the sensor reads −a_r and a_θ
    (§5, the baseline)."""
    M, n, eps, omega = 256, 3, 1e-3, 40.0
    phi = -np.pi + 2 * np.pi * np.arange(M) / M
    w = eps * np.cos(n * phi)
    v = -eps * np.sin(n * phi) / n  # w + v′ = 0
    rad, tan = ind.fd_channels(dict(w=w, v=v), omega)
    np.testing.assert_allclose(rad, omega**2 * (n * n - 1) * w, atol=1e-9 * omega**2 * eps)
    # a_θ = Re(i Ω²(n²−1)/n · W e^{inφ}) = −Ω²(n²−1)/n · eps sin nφ
    np.testing.assert_allclose(tan, -omega**2 * (n * n - 1) / n * eps * np.sin(n * phi), atol=1e-9 * omega**2 * eps)


def test_rolling_fd_balances_the_load_scales_with_speed_and_damping_resists():
    """§4.1: undamped, χ = 1, a stiff membrane — the steady shape does not depend on Ω and the reading scales with
    Ω²; §4.3: Fz = R Σ p cos φ Δφ is the imposed load; §4.2: hysteretic damping shifts the pressure forward and
    gives a rearward Fx = −R ∫ p sin φ dφ > 0 (zero undamped, by symmetry)."""
    n, load = 1024, 4000.0
    h = 2 * np.pi / n
    undamped = RING.replace(damping_ratio=0.0)
    sols = [ind.fd_rolling(undamped, GEOMETRY, load, n, omega=om) for om in (20.0, 60.0)]
    for sol in sols:
        assert GEOMETRY.radius * h * np.sum(sol["p"] * np.cos(sol["phi"])) == pytest.approx(load, rel=1e-10)
    r1, r2 = (ind.fd_channels(s, om)[0] / om**2 for s, om in zip(sols, (20.0, 60.0)))
    assert np.max(np.abs(r1 - r2)) < 1e-4 * np.max(np.abs(r1))
    fx = lambda s: -GEOMETRY.radius * h * np.sum(s["p"] * np.sin(s["phi"]))  # noqa: E731
    damped = ind.fd_rolling(RING, GEOMETRY, load, n, omega=60.0)
    assert abs(fx(sols[1])) < 1e-9 * load
    assert fx(damped) > 1e-3 * load


@pytest.mark.slow  # a fresh interpreter and a whole case: ~15 s
def test_the_case_is_an_identify_folder_and_its_truth_uses_no_ringfit_physics(tmp_path):
    """make_independent_case writes what `ringfit identify FOLDER` reads (docs/formats.md §6), and generating it
    imports nothing of ringfit.physics (run in a fresh interpreter)."""
    code = ("import sys, json; from ringfit.synth.independent import make_independent_case; "
            f"t = make_independent_case({str(tmp_path / 'c')!r}, seed=4); "
            "print(json.dumps(sorted(m for m in sys.modules if m.startswith('ringfit.physics'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
    from ringfit.fit.identify import read_identify_folder

    inputs = read_identify_folder(tmp_path / "c")
    assert len(inputs.loaded) == 2 and len(inputs.profiles) == 3 and len(inputs.free) == 9
    truth = json.loads((tmp_path / "c" / "truth.json").read_text())
    assert truth["resolution"] == "fine" and set(truth["ring"]) >= {"rho_a", "ei", "kw", "kv", "k_tread"}
