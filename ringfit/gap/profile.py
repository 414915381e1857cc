"""The rolling-profile side of the gap diagnosis: baseline ``gong-rolling`` fitted to ``*.profile.csv`` (docs/physics.md §4–6).

The baseline is the inextensible ring with tread springs (§4) read through sensor layer 2 only, each channel's
per-revolution mean removed; the ring comes from the free table's eq. 18 fit, refitted with that fit's posterior as
its prior; k_trd and each run's gain and angle offset (the profile block's nuisances,
:func:`~ringfit.fit.profile_block.read_through`, tied by one sensor's prior) are fitted. Rows are the profiles on
the model grid; the noise is the far-side estimate (:mod:`ringfit.gap.profile_noise`) with a model-resolution
floor (:data:`MODEL_PRECISION`); one speed is held out per fold. Each choice, and why: docs/physics.md §6
(``gong-rolling``).

Example (the profile problem of ``ringfit example case --effect sensor_tilt --out ex``; docs/formats.md §6)::

    from ringfit.gap import effects
    from ringfit.gap.case import read_case
    from ringfit.gap.diagnosis import build_problems

    case = read_case("ex/case")
    *modes, profiles = build_problems(case, tuple(effects.get(n) for n in effects.available()))
    print(profiles.domain, profiles.y.size, profiles.noise_method)
"""

from __future__ import annotations

import dataclasses
from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit._cache import jit
from ringfit.errors import InputError
from ringfit.fit.engine import LINEAR
from ringfit.fit.profile_block import nuisance_coords, nuisance_prior_cov, nuisance_names, nuisance_start, read_through
from ringfit.gap.effects.base import Effect
from ringfit.gap.problem import GapProblem, ProblemMeta
from ringfit.gap.profile_noise import profile_noise
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced
from ringfit.physics.profile import ProfileModel, flat_or_drum, profile_channels

#: Model grid of the diagnosis (docs/physics.md §4.5: within 0.1 % of M = 8192 for the sensor signals).
GRID = 512
#: Baseline parameters always fitted to the profiles: the tread stiffness (log); then the profile block's
#: nuisances per profile (:func:`ringfit.fit.profile_block.nuisance_names`: angle offset [rad], linear; gain, log).
BASE = ("k_tread",)
#: Ring parameters of the baseline also refitted to the profiles, with the free-table fit's Laplace
#: posterior as a correlated log-normal prior (``damping_ratio`` only when the free table has damping).
RING_BASE = ("ei", "kw", "kv", "damping_ratio")
#: log-normal prior σ of k_trd around its starting value (weak: the profiles determine it): the *profile
#: baseline's* prior (docs/physics.md §6, *Where the ring's values come from*), around the tyre file's k_trd or
#: :data:`ringfit.params.DEFAULT_K_TREAD`. Wider than the other two k_trd σ on purpose: k_trd is fitted here to
#: every profile at its stated load (both channels, every speed), so the data pin it and the prior only keeps
#: the fit away from absurd values. The load estimate's (:data:`ringfit.fit.estimate.load.DEFAULT_K_TREAD_SD`,
#: 0.3) must be informative, as its one profile cannot tell k_trd from the unknown load; the loaded-table
#: condition's (:data:`ringfit.gap.modal_conditions.K_TREAD_PRIOR_SD`, 0.5) is not fitted at all but propagated
#: into the contact patch computed from a table's stated load.
K_TREAD_PRIOR_SD = 1.0
#: Prior σ (log) of a ring parameter when the free-table fit gives no usable covariance.
RING_PRIOR_SD_FALLBACK = 0.3
#: Forward-mode tangents per Jacobian pass beyond the baseline's free parameters (one two-parameter effect).
EFFECT_TANGENTS = 2
#: Bootstrap block [rows] for the shrink interval (contiguous angle samples: coloured noise).
BLOCK = 16
#: Screen: a candidate aligned with less than this share of the χ² is not refitted (see screening).
SCREEN_MIN_FRACTION = 0.02
CHANNELS = ("radial", "tangential")
#: Model-resolution floor (radial, tangential) added in quadrature to the noise, × the channel's RMS per
#: profile. Measured: the M = 512 model against M = 4096 (band-limited to harmonic 255, Table 9 tyre, 4 kN,
#: Ω = 18 and 55 rad/s) misses by 1.1e-3 of the channel RMS in the radial channel and by 0.4e-3 in the
#: tangential one for the baseline sensor, 5.5e-3 with the strongest tilt (γ = 1, e = 6 mm: the doublets
#: Ω²e(w‴ + w′)/R at the patch edges are a third derivative). The floor bounds these: below it a
#: residual is discretisation, not physics.
MODEL_PRECISION = np.array([1.5e-3, 6e-3])
#: The baseline's rows are corrected for the model grid's own discretisation by the same model on a grid this many
#: times finer, evaluated once at the baseline fit (a defect correction, docs/physics.md §6 *baselines*).
FINE_FACTOR = 4


class ProfileData(eqx.Module):
    """What the profile predictor needs besides θ: ring, geometry and the operating points ``(P,)``."""

    ring: RingParams
    geometry: TyreGeometry
    omega: jax.Array
    load: jax.Array
    roads: object
    band: jax.Array


def _nuisances(theta, base: tuple, P: int):
    """Each profile's angle offset and gain ``(P,)`` from θ: the block's ``angle_offset_i``/``gain_i``; a single
    ``angle_offset`` is one offset for every profile; no gain is gain 1."""
    off = [theta[i] for i, n in enumerate(base) if n.startswith("angle_offset")]
    gain = [theta[i] for i, n in enumerate(base) if n.startswith("gain_")]
    offset = jnp.stack(off) if len(off) == P else jnp.full((P,), off[0] if off else 0.0)
    return offset, (jnp.stack(gain) if gain else jnp.ones((P,)))


def _is_nuisance(name: str) -> bool:
    return name.startswith(("angle_offset", "gain_"))


def _solved(theta, data: ProfileData, base: tuple, effects: tuple, sizes: tuple, solver: ContactSolver):
    """The composed model's channels ``(P, 2, M)`` before each run's reading (the rolling solve: every θ entry
    but the profile block's nuisances)."""
    ring = data.ring.replace(**{name: theta[i] for i, name in enumerate(base) if not _is_nuisance(name)})
    model = ProfileModel()
    i = len(base)
    for effect, k in zip(effects, sizes):
        model = effect.profile_model(theta[i : i + k], model)
        i += k
    return profile_channels(model, ring, data.geometry, data.omega, data.load, data.roads, data.band, 0.0, solver)


def _read(channels, theta, base: tuple):
    """``(P·2·M,)`` rows: ``channels`` ``(P, 2, M)`` read through each profile's angle offset and gain
    (:func:`ringfit.fit.profile_block.read_through`)."""
    offset, gain = _nuisances(theta, base, channels.shape[0])
    return read_through(channels, offset, gain).reshape(-1)


def _channels(theta, data: ProfileData, base: tuple, effects: tuple, sizes: tuple, solver: ContactSolver):
    """``(P·2·M,)`` rows of the composed model (un-jitted core of the predictors), read through each profile's
    angle offset and gain (:func:`ringfit.fit.profile_block.read_through`)."""
    return _read(_solved(theta, data, base, effects, sizes, solver), theta, base)


class ProfilePredictor(eqx.Module):
    """Prediction of every row of a profile problem: :func:`_channels`, un-jitted (static configuration)."""

    effects: tuple = eqx.field(static=True)
    sizes: tuple = eqx.field(static=True)
    solver: ContactSolver = eqx.field(static=True)
    base: tuple = eqx.field(static=True)

    def __call__(self, theta, data):
        return _channels(theta, data, self.base, self.effects, self.sizes, self.solver)

    # two stages (the engine's two-stage model, via :class:`ringfit.gap.ranking.GapResiduals`): the rolling
    # solve, then each run's reading — so a linearisation passes the nuisances' tangents through the reading
    # only (2P fewer tangents through the solve)
    @property
    def readout(self) -> tuple[int, ...]:
        """θ indices of the profile block's nuisances (they act after the solve)."""
        return tuple(i for i, n in enumerate(self.base) if _is_nuisance(n))

    def inner(self, theta, data):
        """The expensive stage: the rolling solve's model channels (no per-run gain or offset in them)."""
        return _solved(theta, data, self.base, self.effects, self.sizes, self.solver)

    def outer(self, channels, theta, data):
        """The cheap stage: each run's reading of ``channels`` through its own gain and angle offset."""
        return _read(channels, theta, self.base)


@partial(jit, static_argnames=("effects", "sizes", "solver", "base"))
def profile_predict(theta, data: ProfileData, *, effects: tuple, sizes: tuple, solver: ContactSolver,
                    base: tuple = BASE):
    """Predicted rows ``(P·2·M,)`` [m/s²]: profiles × (radial, tangential) × grid angle.

    ``theta`` = [baseline parameters named by ``base`` (natural units: ring fields of
    :class:`~ringfit.params.RingParams`, per profile ``angle_offset_i`` [rad] and ``gain_i`` — or one
    ``angle_offset`` for all), each effect's parameters (``sizes``)]. Default ``base``: k_trd [N/m²] alone.
    """
    return _channels(theta, data, base, effects, sizes, solver)


def _band(profiles, M: int) -> tuple[np.ndarray, np.ndarray]:
    k = np.arange(M // 2 + 1)
    kmax = np.array([(min(len(p), M) - 1) // 2 for p in profiles])
    kmax = np.minimum(kmax, M // 2 - 1)  # Nyquist zeroed (docs/physics.md §4.5)
    return (k[None, :] <= kmax[:, None]).astype(np.float64), kmax


def _folds(P: int, M: int) -> tuple[np.ndarray, str]:
    rows = np.arange(P * 2 * M)
    if P >= 2:
        return rows // (2 * M), "leave-one-speed-out"
    j = rows % M
    return (j // BLOCK) % 4, "interleaved 16-sample angle blocks (one profile: no speed to leave out)"


def build_profile_problem(case, ring: RingParams, effects: tuple[Effect, ...], noise: dict | None = None,
                          sources: dict | None = None, grid: int = GRID, ring_prior: dict | None = None) -> GapProblem:
    """Assemble the profile problem of a case: rows, baseline fit, noise, folds, the applicable effects.

    **Arguments:** ``case`` — a :class:`ringfit.gap.case.Case` with profiles; ``ring`` — the ring
    from the free-table fit (``k_tread`` = starting value); ``effects`` — candidates; ``noise`` —
    optional ``{"profile_ms2": σ}``; ``sources`` — where each ring value came from (for the JSON);
    ``ring_prior`` — optional ``{"names": (…), "cov": (k, k)}``: ring fields of :data:`RING_BASE`
    refitted to the profiles and the covariance of their logs from the free-table fit (the prior
    of the refit). ``None``: the ring stays as given and only k_trd and the angle offset are fitted.
    """
    from ringfit.fit.profile_block import rolling_data
    from ringfit.io.profiles import grid_angles_deg
    from ringfit.gap.ranking import fit_chain, predict

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
    ring_names = tuple(ring_prior["names"]) if ring_prior else ()
    P = len(profiles)
    nuis = nuisance_names(P)  # the profile block's per-run nuisances, as identify fits them
    base = BASE + nuis + ring_names
    nb = len(base)
    nuis_coords = nuisance_coords(P)
    linear = tuple(c.kind == LINEAR for c in nuis_coords)

    def prepare(ring_now):
        d = rolling_data(profiles, geometry, ring_now, solver=solver)
        return d, ProfileData(ring=as_traced(ring_now), geometry=as_traced(geometry), omega=jnp.asarray(d.omega),
                              load=jnp.asarray(d.load), roads=flat_or_drum(d.drum_diameter, len(profiles)),
                              band=jnp.asarray(band))

    rdata, data = prepare(ring)
    y = rdata.measured.reshape(-1)
    folds, fold_kind = _folds(P, M)
    phi_deg = grid_angles_deg(M)
    labels = {
        "angle_deg": np.tile(phi_deg, 2 * P),
        "channel": np.tile(np.repeat(np.array(CHANNELS), M), P),
        "speed_kmh": np.repeat(rdata.speed_kmh, 2 * M),
        "profile": np.repeat(np.arange(P), 2 * M),
    }
    labels["group"] = labels["channel"]
    labels["series"] = np.repeat(np.arange(2 * P), M)  # one noise series per profile and channel

    k0 = float(ring.k_tread)
    values = np.concatenate([[k0], nuisance_start(P), [float(getattr(ring, n)) for n in ring_names]])
    cov = np.diag([K_TREAD_PRIOR_SD**2] + [0.0] * len(nuis) + [0.0] * len(ring_names))
    cov[1 : 1 + len(nuis), 1 : 1 + len(nuis)] = nuisance_prior_cov(P)  # the runs share one sensor
    if ring_names:
        cov[1 + len(nuis):, 1 + len(nuis):] = np.asarray(ring_prior["cov"], dtype=np.float64)
    problem = GapProblem(
        domain="profiles", data_files=[str(p.source).rsplit("/", 1)[-1] for p in profiles], y=y,
        sigma=np.full(y.shape, max(float(np.std(y)), 1e-9)), unit="m/s^2", scale=np.ones_like(y), folds=folds,
        fold_kind=fold_kind, labels=labels, base=base, base_values=values.copy(),
        base_prior_sd=np.sqrt(np.diag(cov)), effects=usable, data=data,
        noise_method="", baseline_model="gong-rolling", not_applicable=dropped,
        meta=ProblemMeta(block=BLOCK, tangents=nb + EFFECT_TANGENTS, screen_min_fraction=SCREEN_MIN_FRACTION,
                         k_max=kmax, omega=rdata.omega, omega_source=list(rdata.omega_source),
                         prior_guarded=(0,) + tuple(range(1 + len(nuis), nb)),
                         # leave-one-speed-out: a held-out run's own gain and offset are fitted to it
                         fold_nuisances={i: (1 + 2 * i, 2 + 2 * i) for i in range(P)} if P >= 2 else {}),
        base_linear=(False,) + linear + (False,) * len(ring_names),
        base_linear_scale=(1.0,) + tuple(c.scale for c in nuis_coords) + (1.0,) * len(ring_names),
        base_linear_bound=(1.0,) + tuple(c.hi if c.kind == LINEAR else 1.0 for c in nuis_coords)
        + (1.0,) * len(ring_names),
        base_coords={c.name: c for c in nuis_coords},
        base_prior_mean=values.copy(), base_prior_cov=cov,
        predictor=ProfilePredictor(usable, sizes, solver, base),
    )
    phi = np.radians(phi_deg)
    user = (noise or {}).get("profile_ms2")
    for it in range(2):  # σ weights the fit, the fit's residual gives σ: two passes
        theta = fit_chain(problem, ()).theta
        problem.base_values = theta[:nb].copy()
        if it == 0 and not has_encoder:  # Ω = V/R_e with the fitted baseline's deflection
            fitted = ring.replace(**{n: float(v) for n, v in zip(base, theta) if not _is_nuisance(n)})
            rdata, problem.data = prepare(fitted)
            y = rdata.measured.reshape(-1)
            problem.meta.omega, problem.meta.omega_source = rdata.omega, list(rdata.omega_source)
        if it == 0:  # the grid's own discretisation error at the first fit, taken off the rows (a defect correction)
            correction = grid_defect(theta[:nb], problem.data, base, solver,
                                     coarse=predict(problem, problem.null_theta()))
            problem.y = y = y + correction
            theta = fit_chain(problem, ()).theta
            problem.base_values = theta[:nb].copy()
        resid = (y - predict(problem, problem.null_theta())).reshape(P, 2, M)
        if user is not None:
            sigma, slope = np.full((P, 2), float(user)), 0.0
            dof = np.array([[2.0 * kmax[i]] * 2 for i in range(P)])  # white noise of the stated σ
            problem.noise_method = f"user value {float(user):.3g} m/s^2 (white)"
        else:
            sigma, slope, dof = profile_noise(resid, phi, kmax)
            # model-resolution floor: the M = 512 grid reproduces the sensor signals to ~0.1 % of their
            # peaks (docs/physics.md §4.5); below that a residual is discretisation, not physics
            floor = MODEL_PRECISION[None, :] * np.sqrt(np.mean(rdata.measured**2, axis=-1))
            sigma = np.sqrt(sigma**2 + floor**2)
            problem.noise_method = (
                "per profile and channel from the far side of the wheel (|angle| > 90 deg, cos^4 taper): "
                "the residual's periodogram summed from harmonic 8 up, below it a power law fitted to octave-band "
                "levels and extrapolated to harmonic 1, "
                f"plus {MODEL_PRECISION[0]:g} (radial) / {MODEL_PRECISION[1]:g} (tangential) x channel RMS "
                "(model resolution, M = 512 against M = 4096) in quadrature; "
                "sigma [m/s^2] " + ", ".join(f"{s:g} km/h: {sigma[i, 0]:.3g}/{sigma[i, 1]:.3g}"
                                             for i, s in enumerate(rdata.speed_kmh)))
            problem.meta.noise_slope = slope
            problem.noise_method += f"; spectral slope {slope:.2f}"
        problem.sigma = np.repeat(sigma.reshape(-1), M)
        problem.meta.series_dof = {2 * i + c: float(dof[i, c]) for i in range(P) for c in range(2)}
    c2 = correction.reshape(P, 2, M)
    rel = np.sqrt(np.mean(c2**2, axis=-1)) / np.maximum(np.sqrt(np.mean(rdata.measured**2, axis=-1)), 1e-300)
    problem.noise_method += (f"; rows corrected for the M = {M} grid's own error against M = {FINE_FACTOR * M} at the "
                             f"baseline fit (largest {np.max(rel[:, 0]):.2g} of the radial RMS, "
                             f"{np.max(rel[:, 1]):.2g} of the tangential)")
    if user is None:  # the far-side estimate repeated on every parametric-null draw, as it was made on the data
        problem.meta.noise_rule = partial(_profile_rule, phi=phi, kmax=np.asarray(kmax), floor=floor,
                                                    shape=(P, 2, M))
    problem.meta.sources = dict(sources or {})
    problem.meta.sources["k_tread"] = "fitted to the profiles"
    for n in ring_names:
        problem.meta.sources[n] = (problem.meta.sources.get(n, "free-table fit")
                                      + "; refitted to the profiles with that fit's uncertainty as prior")
    problem.meta.sources["omega"] = sorted(set(rdata.omega_source))
    return problem


def grid_defect(theta, data: ProfileData, base: tuple, solver: ContactSolver, factor: int = FINE_FACTOR,
                coarse=None) -> np.ndarray:
    """``(P·2·M,)`` the baseline model's rows on the problem's grid minus the same model's on a grid ``factor``
    times finer, read at the same angles (both band-limited to the data's band, so the finer grid's every
    ``factor``-th sample is exact): the discretisation error of the M-point model at ``theta`` (baseline
    parameters named by ``base``): it leaves the model to be judged against the
    data, not against its own grid (docs/physics.md §6 *baselines*, gong-rolling). Added to the measured rows
    (y ≈ fine + noise), it gives rows the M-point model would read: y + (coarse − fine). ``coarse``: the M-point
    rows at ``theta`` where the caller has them (the problem's own compiled prediction; else computed here)."""
    M = solver.n_grid
    fine = dataclasses.replace(solver, n_grid=factor * M)
    band = np.asarray(data.band)
    fine_band = np.zeros((band.shape[0], factor * M // 2 + 1))
    fine_band[:, : band.shape[1]] = band  # the data's band (the coarse grid's Nyquist is already out of it)
    theta = jnp.asarray(theta, dtype=jnp.float64)
    if coarse is None:
        coarse = profile_predict(theta, data, effects=(), sizes=(), solver=solver, base=base)
    coarse = np.asarray(coarse, dtype=np.float64)
    f = profile_predict(theta, eqx.tree_at(lambda d: d.band, data, jnp.asarray(fine_band)), effects=(), sizes=(),
                        solver=fine, base=base)
    P = band.shape[0]
    return coarse - np.asarray(f).reshape(P, 2, factor * M)[..., ::factor].reshape(-1)


def _profile_rule(rows, center, *, phi, kmax, floor, shape) -> np.ndarray:
    """σ ``(B, m)`` of profile rows ``(B, m)`` by the problem's noise rule (:func:`profile_noise` of each run and
    channel's residual about ``center`` ``(m,)``, the model the draw was made from, with the model-resolution
    ``floor`` ``(P, 2)`` in quadrature): the ``noise_rule`` the parametric null applies to every draw."""
    rows = np.atleast_2d(np.asarray(rows, dtype=np.float64))
    P, C, M = shape
    out = np.empty_like(rows)
    for b in range(rows.shape[0]):
        sigma, _, _ = profile_noise((rows[b] - center).reshape(P, C, M), phi, kmax, dof=False)
        out[b] = np.repeat(np.sqrt(sigma**2 + floor**2).reshape(-1), M)
    return out


__all__ = ["K_TREAD_PRIOR_SD", "MODEL_PRECISION", "grid_defect", "build_profile_problem", "profile_predict", "ProfilePredictor", "ProfileData",
           "BASE", "RING_BASE", "GRID"]
