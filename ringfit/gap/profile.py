"""The rolling-profile side of the gap diagnosis: baseline ``gong-rolling`` fitted to ``*.profile.csv`` (PHYSICS.md §4–6).

**Baseline** (PHYSICS.md §6): the inextensible ring with χ = 1, hysteretic
damping and radial frictionless tread springs (§4), read through sensor
layer 2 only (γ = 0, e = 0, no g, no high-pass), each channel's
per-revolution mean removed. The ring's ρA, EI, k_w, k_v come from the eq. 18
fit to ``free.modes.csv`` (:mod:`ringfit.gap.modal`), its damping ratio from
that table's damping column (else ``tyre.toml``); the tread stiffness k_trd is
fitted to the profiles (starting at ``tyre.toml``'s value or 19e6 N/m²),
together with one recorded-angle offset for all profiles (a nuisance, fitted
linearly within ±10°, PHYSICS.md §5 layer 6). The JSON says which source
each value came from (``baseline.sources``).

**Rows**: every profile (one per speed), both channels, band-limited
resampled onto the model grid φ_j (M = 512, PHYSICS.md §4.5) with its mean
removed (:func:`ringfit.fit.rolling.rolling_data`); the model is band-limited
to the harmonics each measurement holds. Ω from the sidecar's
``rotation_hz``, else V/R_e with R_e = R_out − δ/3 of the fitted baseline
(recomputed after the first baseline fit).

**Noise**: from the far side of the wheel (:mod:`ringfit.gap.profile_noise`),
per profile and channel, or the user's ``noise={"profile_ms2": σ}``.

**Held-out**: leave-one-speed-out (one fold per profile); with a single
profile, interleaved 16-sample angle blocks (4 folds).

**Candidates**: every effect with a profile hook (sensor_tilt, gravity,
iepe_highpass, wave_damping, tread_shear, rotation (χ), ring_extensibility
(EA), sensor_mass); the model of each is composed by
:class:`ringfit.gap.profile_model.ProfileModel`. One jitted predictor and one
jitted set of forward-mode tangents (K fixed) serve every candidate, chain
and case with the same number of profiles.
"""

from __future__ import annotations

import math
from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.gap.effects.base import Effect
from ringfit.gap.problem import GapProblem
from ringfit.gap.profile_model import ProfileModel, profile_channels
from ringfit.gap.profile_noise import profile_noise
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced

#: Model grid of the diagnosis (PHYSICS.md §4.5: within 0.1 % of M = 8192 for the sensor signals).
GRID = 512
#: Baseline parameters of the profile side: tread stiffness (log) and the angle offset [rad] (linear).
BASE = ("k_tread", "angle_offset")
#: Angle-offset bound and scale [rad].
OFFSET_BOUND = math.radians(10.0)
OFFSET_SCALE = math.radians(1.0)
#: log-normal prior σ of k_trd around its starting value in refits (weak).
K_TREAD_PRIOR_SD = 1.0
#: Forward-mode tangents per Jacobian call (free parameters of the largest chain fit at once).
TANGENTS = 6
#: Bootstrap block [rows] for the shrink interval (contiguous angle samples: coloured noise).
BLOCK = 16
#: Screen: a candidate aligned with less than this share of the χ² is not refitted (see screening).
SCREEN_MIN_FRACTION = 0.02
CHANNELS = ("radial", "tangential")
#: Relative model precision added in quadrature to the noise (per profile and channel, × the channel's RMS).
MODEL_PRECISION = 2e-3


class ProfileData(eqx.Module):
    """What the profile predictor needs besides θ: ring, geometry and the operating points ``(P,)``."""

    ring: RingParams
    geometry: TyreGeometry
    omega: jax.Array
    load: jax.Array
    roads: object
    band: jax.Array


def _compose(theta, effects, sizes):
    model = ProfileModel()
    i = len(BASE)
    for effect, k in zip(effects, sizes):
        model = effect.profile_model(theta[i : i + k], model)
        i += k
    return model


@partial(jax.jit, static_argnames=("effects", "sizes", "solver"))
def profile_predict(theta, data: ProfileData, *, effects: tuple, sizes: tuple, solver: ContactSolver):
    """Predicted rows ``(P·2·M,)`` [m/s²]: profiles × (radial, tangential) × grid angle.

    ``theta`` = [k_trd [N/m²], angle offset [rad], each effect's parameters (``sizes``)], natural units.
    """
    ring = data.ring.replace(k_tread=theta[0])
    model = _compose(theta, effects, sizes)
    ch = profile_channels(model, ring, data.geometry, data.omega, data.load, data.roads, data.band, theta[1], solver)
    return ch.reshape(-1)


@partial(jax.jit, static_argnames=("effects", "sizes", "solver"))
def profile_tangents(theta, data: ProfileData, basis, *, effects: tuple, sizes: tuple, solver: ContactSolver):
    """Directional derivatives ``(m, K)`` of :func:`profile_predict` along the columns of ``basis`` ``(p, K)``."""
    f = lambda th: profile_predict(th, data, effects=effects, sizes=sizes, solver=solver)  # noqa: E731
    return jax.vmap(lambda t: jax.jvp(f, (theta,), (t,))[1], in_axes=1, out_axes=1)(basis)


def _band(profiles, M: int) -> tuple[np.ndarray, np.ndarray]:
    k = np.arange(M // 2 + 1)
    kmax = np.array([(min(len(p), M) - 1) // 2 for p in profiles])
    kmax = np.minimum(kmax, M // 2 - 1)  # Nyquist zeroed (PHYSICS.md §4.5)
    return (k[None, :] <= kmax[:, None]).astype(np.float64), kmax


def _folds(P: int, M: int) -> tuple[np.ndarray, str]:
    rows = np.arange(P * 2 * M)
    if P >= 2:
        return rows // (2 * M), "leave-one-speed-out"
    j = rows % M
    return (j // BLOCK) % 4, "interleaved 16-sample angle blocks (one profile: no speed to leave out)"


def build_profile_problem(case, ring: RingParams, effects: tuple[Effect, ...], noise: dict | None = None,
                          sources: dict | None = None, grid: int = GRID) -> GapProblem:
    """Assemble the profile problem of a case: rows, baseline fit, noise, folds, the applicable effects.

    **Arguments:** ``case`` — a :class:`ringfit.gap.case.Case` with profiles; ``ring`` — the ring
    from the free-table fit (``k_tread`` = starting value); ``effects`` — candidates; ``noise`` —
    optional ``{"profile_ms2": σ}``; ``sources`` — where each ring value came from (for the JSON).
    """
    from ringfit.fit.rolling import rolling_data
    from ringfit.gap.ranking import fit_chain

    profiles = list(case.profiles)
    if not profiles:
        raise InputError("no *.profile.csv in the case folder", source=case.folder)
    geometry = case.tyre.geometry
    solver = ContactSolver(n_grid=grid)
    M = solver.n_grid
    usable, dropped = [], {}
    for e in effects:
        if e.speaks_to_profiles:
            usable.append(e)
        else:
            dropped[e.name] = "does not act on rolling profiles"
    usable = tuple(usable)
    sizes = tuple(len(e.params_for("profiles")) for e in usable)
    band, kmax = _band(profiles, M)
    has_encoder = all(p.rotation_hz is not None for p in profiles)

    def prepare(ring_now):
        d = rolling_data(profiles, geometry, ring_now, solver=solver)
        return d, ProfileData(ring=as_traced(ring_now), geometry=as_traced(geometry), omega=jnp.asarray(d.omega),
                              load=jnp.asarray(d.load), roads=d.roads, band=jnp.asarray(band))

    rdata, data = prepare(ring)
    P = rdata.measured.shape[0]
    y = rdata.measured.reshape(-1)
    folds, fold_kind = _folds(P, M)
    phi_deg = -180.0 + 360.0 * np.arange(M) / M
    labels = {
        "angle_deg": np.tile(phi_deg, 2 * P),
        "channel": np.tile(np.repeat(np.array(CHANNELS), M), P),
        "speed_kmh": np.repeat(rdata.speed_kmh, 2 * M),
        "profile": np.repeat(np.arange(P), 2 * M),
    }
    labels["group"] = labels["channel"]
    predict = partial(profile_predict, effects=usable, sizes=sizes, solver=solver)
    tangents = partial(profile_tangents, effects=usable, sizes=sizes, solver=solver)
    k0 = float(ring.k_tread)
    problem = GapProblem(
        domain="profiles", data_files=[str(p.source).rsplit("/", 1)[-1] for p in profiles], y=y,
        sigma=np.full(y.shape, max(float(np.std(y)), 1e-9)), unit="m/s^2", scale=np.ones_like(y), folds=folds,
        fold_kind=fold_kind, labels=labels, base=BASE, base_values=np.array([k0, 0.0]),
        base_prior_sd=np.array([K_TREAD_PRIOR_SD, np.inf]), effects=usable, predict=predict, data=data,
        noise_method="", baseline_model="gong-rolling", not_applicable=dropped,
        meta={"block": BLOCK, "tangents": TANGENTS, "screen_min_fraction": SCREEN_MIN_FRACTION,
              "k_max": kmax, "omega": rdata.omega, "omega_source": list(rdata.omega_source)},
        base_linear=(False, True), base_linear_scale=(1.0, OFFSET_SCALE), base_linear_bound=(1.0, OFFSET_BOUND),
        jacobian=tangents,
    )
    phi = np.radians(phi_deg)
    user = (noise or {}).get("profile_ms2")
    for it in range(2):  # σ weights the fit, the fit's residual gives σ: two passes
        theta = fit_chain(problem, ()).theta
        problem.base_values = theta[: len(BASE)].copy()
        if it == 0 and not has_encoder:  # Ω = V/R_e with the fitted tread stiffness's deflection
            rdata, problem.data = prepare(ring.replace(k_tread=float(theta[0])))
            problem.y = y = rdata.measured.reshape(-1)
            problem.meta.update(omega=rdata.omega, omega_source=list(rdata.omega_source))
        resid = (y - np.asarray(predict(jnp.asarray(problem.null_theta()), problem.data))).reshape(P, 2, M)
        if user is not None:
            sigma = np.full((P, 2), float(user))
            problem.noise_method = f"user value {float(user):.3g} m/s^2"
        else:
            sigma, slope = profile_noise(resid, phi, kmax)
            # model-resolution floor: the M = 512 grid reproduces the sensor signals to ~0.1 % of their
            # peaks (PHYSICS.md §4.5); below that a residual is discretisation, not physics
            floor = MODEL_PRECISION * np.sqrt(np.mean(rdata.measured**2, axis=-1))
            sigma = np.sqrt(sigma**2 + floor**2)
            problem.noise_method = (
                "per profile and channel from the far side of the wheel (|angle| > 90 deg, cos^4 taper): "
                "power law fitted to the residual spectrum above harmonic 8, extrapolated to harmonic 1, "
                f"plus {MODEL_PRECISION:g} x channel RMS (model resolution) in quadrature; "
                "sigma [m/s^2] " + ", ".join(f"{s:g} km/h: {sigma[i, 0]:.3g}/{sigma[i, 1]:.3g}"
                                             for i, s in enumerate(rdata.speed_kmh)))
            problem.meta["noise_slope"] = slope
            problem.noise_method += f"; spectral slope {slope:.2f}"
        problem.sigma = np.repeat(sigma.reshape(-1), M)
    problem.meta["sources"] = dict(sources or {})
    problem.meta["sources"]["k_tread"] = "fitted to the profiles"
    problem.meta["sources"]["omega"] = sorted(set(rdata.omega_source))
    return problem


__all__ = ["build_profile_problem", "profile_predict", "profile_tangents", "ProfileData", "BASE", "GRID"]
