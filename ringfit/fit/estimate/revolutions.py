"""Load and patch revolution by revolution of a continuous recording (docs/physics.md §10; docs/formats.md §7).

:func:`recording_revolutions` walks the recording once (harmonics of every whole revolution, their
average as a profile); :func:`estimate_revolutions` fits each revolution in batches on the engine with
the nuisances of the averaged profile's fit; :func:`estimate_recording` does both.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Literal, get_args

import jax
import numpy as np

from ringfit.errors import InputError
from ringfit.fit.engine import least_squares, least_squares_batch
from ringfit.fit.estimate.feature import _num, edge_peaks
from ringfit.fit.estimate.harmonics import harmonic_amplitudes, amplitude_rows
from ringfit.fit.estimate.load import LoadEstimate, estimate_load
from ringfit.fit.estimate.problem import ANGLE_OFFSET, GAIN, LOAD, EstimateArrays, EstimateSettings, estimate_problem
from ringfit.fit.profile_block import noise_from_residual
from ringfit.io.profiles import grid_angles_deg
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import as_traced
from ringfit.physics.profile import flat_or_drum
from ringfit.targets.cleat import QUIET_SHARE

#: Revolutions fitted in one call of the engine (one compiled vmap or scan; the last batch is padded).
#: 16 is the fastest on a CPU (benchmarks/bench_estimate.py); an accelerator wants more.
REVOLUTION_BATCH = 16
#: How :func:`estimate_revolutions` runs a batch: ``"batch"`` (vmapped) or ``"chain"`` (one ``lax.scan``, each fit
#: warm-started from the previous revolution's).
RevolutionMode = Literal["batch", "chain"]
#: Per-revolution Gauss–Newton tolerances (Cauchy test on the solver coordinates and the residual rows;
#: near the optimum the steps shrink fast, so the error left after the last step is far below the
#: per-revolution standard error of ~0.2–0.3 %) and step cap.
REVOLUTION_TOL = 1e-4
REVOLUTION_MAX_STEPS = 30
#: The per-revolution outlier rule (docs/physics.md §10, *a revolution the recording does not vouch for*): a
#: revolution whose residual scale s_r departs from its neighbours' median (±:data:`OUTLIER_NEIGHBOURS`
#: revolutions) by more than :data:`OUTLIER_Z` robust standard deviations of ln s is rejected.
OUTLIER_Z = 5.0
#: A channel whose largest swing within a revolution stays under this share of ω²R (the centripetal acceleration
#: that the patch takes away from the radial reading, and of whose order the tangential reading swings there) is
#: dead: its sensor axis, cable or amplifier gives nothing the model could read (docs/physics.md §10).
DEAD_SWING_SHARE = 0.01
#: R of that test when no tyre geometry is given: below any car tyre's outer radius [m].
DEAD_SWING_RADIUS_M = 0.2
OUTLIER_NEIGHBOURS = 10


@dataclass
class RevolutionEstimates:
    """Per-revolution estimates of a continuous recording (arrays of shape ``(R,)``).

    ``revolution`` (numbers counted from the recording's first angle), ``t_s`` (middle of the
    revolution [s]), ``rotation_hz`` (encoder), ``load_n``, ``lo``, ``hi`` (95 % Laplace interval [N];
    statistical: the high-pass corner, tilt and k_trd are fixed at the averaged profile's fit),
    ``length_mm`` (patch length of the model at the load), ``gain``, ``angle_offset_deg``, ``rms``
    [m/s²] (residual in the fitted band), ``converged`` (the fit settled inside the model's range and the
    revolution passed the outlier rule), ``iterations``, ``feature_load_n`` (the classic method on the
    revolution); ``window_deg``: the contact window used; ``residual_ratio``: the revolution's residual scale
    over its neighbours' median and ``outlier`` where that rejected it (:func:`residual_outliers`).
    """

    revolution: np.ndarray
    t_s: np.ndarray
    rotation_hz: np.ndarray
    load_n: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    length_mm: np.ndarray
    gain: np.ndarray
    angle_offset_deg: np.ndarray
    rms: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    feature_load_n: np.ndarray
    window_deg: float = 0.0
    #: recordings with a cleat trigger: ``(R,)`` share of each revolution's angles read in a hit's ringing
    cleat_share: np.ndarray | None = None
    residual_ratio: np.ndarray | None = None
    outlier: np.ndarray | None = None

    #: Columns of the per-revolution CSV (docs/formats.md §7), in order.
    COLUMNS = ("revolution", "t_s", "rotation_hz", "load_n", "lo", "hi", "patch_length_mm", "gain",
               "angle_offset_deg", "rms_ms2", "converged", "feature_load_n")

    def __len__(self) -> int:
        return self.revolution.size

    def columns(self) -> dict:
        """Column name → ``(R,)`` array, in :attr:`COLUMNS` order."""
        return {"revolution": self.revolution, "t_s": self.t_s, "rotation_hz": self.rotation_hz,
                "load_n": self.load_n, "lo": self.lo, "hi": self.hi, "patch_length_mm": self.length_mm,
                "gain": self.gain, "angle_offset_deg": self.angle_offset_deg, "rms_ms2": self.rms,
                "converged": self.converged.astype(int), "feature_load_n": self.feature_load_n,
                **({} if self.residual_ratio is None else {"residual_ratio": self.residual_ratio}),
                **({} if self.cleat_share is None else {"cleat_share": self.cleat_share})}

    def summary(self) -> dict:
        """Counts and the load's range over the revolutions (for the JSON)."""
        ok = self.converged
        load = self.load_n[ok]
        return {"revolutions": int(len(self)), "converged": int(ok.sum()),
                "outliers": int(np.sum(self.outlier)) if self.outlier is not None else 0,
                "load_n_median": _num(np.median(load)) if load.size else None,
                "load_n_min": _num(load.min()) if load.size else None,
                "load_n_max": _num(load.max()) if load.size else None,
                "contact_window_deg": float(self.window_deg)}


def _turned(grid_signal: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """A signal on the revolution's grid (M points) with each harmonic's interpolation phase turned back, the modulus
    kept: harmonic k times conj(H_k)/|H_k|, ``gain`` H of harmonics 1 … M/2
    (:func:`~ringfit.targets.rolling_profile.interpolation_response`)."""
    spec = np.fft.rfft(grid_signal)
    spec[1:] *= np.conj(gain) / np.abs(gain)
    return np.fft.irfft(spec, n=grid_signal.size)


@dataclass
class RecordingRevolutions:
    """One pass over a continuous recording: each whole revolution's radial harmonics and the average.

    ``rows`` ``(R, 2K)`` harmonic rows k = 2…k_max (:func:`amplitude_rows`) [m/s²]; ``revolution``,
    ``t_s``, ``rotation_hz`` ``(R,)``; ``profile``: the averaged profile (docs/formats.md §3, the
    revolution-to-revolution spread as ``acc_radial_spread_ms2``); ``response`` ``(K,)``: the resampling's
    gain on the harmonics (the modulus of linear interpolation's at the grid points where they fell between
    samples, :func:`~ringfit.targets.rolling_profile.interpolation_response`: 1 for sampling locked to the angle,
    sinc²(k/samples per revolution) for fractions spread evenly; its phase is turned back out of the rows and the
    profile); ``k_max``; ``noise``
    ``(M,)`` the standard error of the averaged profile per angle [m/s²], from the differences of
    successive revolutions (a load that changes does not count as noise, unlike in the spread).
    """

    rows: np.ndarray
    revolution: np.ndarray
    t_s: np.ndarray
    rotation_hz: np.ndarray
    profile: object
    response: np.ndarray
    k_max: int
    noise: np.ndarray | None = None
    rotation_source: str = "encoder (mean over the recording)"
    #: with a cleat trigger: ``(R,)`` share of each revolution's angles read in a hit's ringing (else None)
    cleat_share: np.ndarray | None = None
    noise_source: str = "differences of successive revolutions / √(2·revolutions), in the fitted band"
    #: with ``tangential=True``: ``(R, 2K)`` the tangential channel's harmonic rows (the profile then holds its mean)
    rows_tangential: np.ndarray | None = None


def refuse_dead_channel(axis: str, swing: float, omega: float, geometry: TyreGeometry | None, source) -> None:
    """Refuse a channel whose largest swing within a revolution [m/s²] stays under :data:`DEAD_SWING_SHARE` of ω²R
    (ω [rad/s]; R the tyre's outer radius, :data:`DEAD_SWING_RADIUS_M` without a geometry): one line naming the
    channel (docs/physics.md §10 *a dead channel*). A recording's channels (:func:`recording_revolutions`) and a
    profile's tangential channel for the state (:func:`ringfit.fit.estimate.state.estimate_state`) both."""
    radius = float(geometry.outer_radius) if geometry is not None else DEAD_SWING_RADIUS_M
    floor = DEAD_SWING_SHARE * omega**2 * radius
    if not swing >= floor:
        raise InputError(f"the {axis} channel is dead: its largest swing within a revolution is {swing:.3g} m/s², "
                         f"under {100 * DEAD_SWING_SHARE:g} % of ω²R = {floor / DEAD_SWING_SHARE:.3g} m/s² (the patch "
                         f"moves a working {axis} reading by about ω²R); check the sensor axis, its cable and "
                         "amplifier" + (", or estimate the load alone (without --state)" if axis == "tangential"
                                        else ""), source=source)


def first_rotation_hz(record, samples: int = 1 << 18) -> float:
    """Rotation rate [Hz] over the first ``samples`` samples of a recording (from its encoder)."""
    n = int(min(samples, record.samples))
    ch = next(record.chunks(n, stop=n, acc=False))
    rate = (ch.angle_deg[-1] - ch.angle_deg[0]) / 360.0 / ((n - 1) / record.fs_hz)
    if not rate > 0:
        raise InputError("the encoder angle does not advance over the first samples: is the wheel turning?",
                         source=record.source)
    return float(rate)


def recording_revolutions(record, *, k_max: int = EstimateSettings.k_max, progress: bool = False,
                          geometry: TyreGeometry | None = None, tangential: bool = False,
                          clamp: bool = False) -> RecordingRevolutions:
    """Walk a continuous recording once (bounded memory): every whole revolution's radial reading on
    the angle grid (:func:`ringfit.targets.rolling_profile.revolution_grids`, M = the power of two at or
    above the samples per revolution, so that every sample takes part), its harmonics 2…k_max, and
    their average and spread over revolutions as a profile.

    The sensor angle comes from the encoder; a recording without one gets it from the patch
    passages in the radial reading (:func:`ringfit.targets.rolling_profile.patch_passages`, one more
    pass): φ = 0 at each passage, linear in time in between (the angle offset then takes up where
    the dip sits relative to the patch centre).

    ``tangential``: read the tangential channel too (the state estimate, docs/physics.md §13.4): its rows per
    revolution and its average in the profile. ``clamp``: with too few samples per revolution for harmonic
    ``k_max``, read the harmonics they resolve (at least 8) instead of raising (the state's wide default band).

    **Raises** :class:`InputError` without a radial axis (or, with ``tangential``, a tangential one), without an
    encoder and without clear patch passages, with fewer than 2 whole revolutions, or with too few samples per
    revolution.
    """
    from ringfit.io.profiles import Profile
    from ringfit.targets.rolling_profile import (FRACTION_BINS, interpolation_response, patch_passages,
                                                 revolution_grids)

    if "radial" not in record.axes:
        raise InputError(f"no 'radial' axis (have: {', '.join(record.axes)}); the estimate reads the radial channel",
                         source=record.source)
    if tangential and "tangential" not in record.axes:
        raise InputError(f"no 'tangential' axis (have: {', '.join(record.axes)}); the state estimate reads the radial "
                         "and tangential channels (the load alone: without --state)", source=record.source)
    passages = None
    if record.has_encoder:
        spr = record.fs_hz / first_rotation_hz(record)
        source = "encoder (mean over the recording)"
    else:  # the sensor angle from the patch passages in the reading itself
        passages = patch_passages(record, progress=progress)
        spr = float(np.median(np.diff(passages)))
        source = "patch passages in the radial reading (no encoder; mean over the recording)"
    if clamp and spr < 4 * (k_max + 2):
        k_max = max(8, int(spr // 4) - 2)
    if spr < 4 * (k_max + 2):
        raise InputError(f"{spr:.0f} samples per revolution are too few to resolve harmonic {k_max} "
                         f"(need ≥ {4 * (k_max + 2)})", source=record.source)
    points = int(min(4096, max(128, 2 ** math.ceil(math.log2(spr)))))
    hits = cleat_windows(record, progress=progress)
    rows, rev, t_s, rate, hit, rows_t = [], [], [], [], [], []
    t1 = np.zeros((2, points))
    fractions = np.zeros((3, FRACTION_BINS))
    # sums over revolutions per angle [0] of every revolution, [1] of those read outside a cleat hit's ringing
    s1, s2, sd = np.zeros((2, points)), np.zeros((2, points)), np.zeros((2, points))
    count, pairs = np.zeros((2, points)), np.zeros((2, points))
    previous = None
    axes = ("radial", "tangential") if tangential else ("radial",)
    swing = np.zeros(len(axes))  # each channel's largest swing within one revolution [m/s²]
    for block in revolution_grids(record, points=points, axes=axes, passages=passages, progress=progress):
        swing = np.maximum(swing, np.max(np.ptp(block.values, axis=2), axis=1))
        values = block.values[0]
        fractions += block.fractions
        rows.append(harmonic_amplitudes(values, 2, k_max))  # complex: made rows once the gain's phase is known
        rev.append(block.revolution)
        t_s.append(block.t_s)
        rate.append(block.rotation_hz)
        quiet = np.ones(values.shape) if hits is None else _quiet(block, points, *hits).astype(np.float64)
        hit.append(1.0 - quiet.mean(axis=1))
        if tangential:
            tv = block.values[1]
            rows_t.append(harmonic_amplitudes(tv, 2, k_max))
            t1[0] += tv.sum(axis=0)
            t1[1] += (quiet * tv).sum(axis=0)
        chain = values if previous is None else np.concatenate([previous[0], values])
        for i, w in enumerate((np.ones(values.shape), quiet)):
            s1[i] += (w * values).sum(axis=0)
            s2[i] += (w * values**2).sum(axis=0)
            count[i] += w.sum(axis=0)
            q = w if previous is None else np.concatenate([previous[1 + i], w])
            both = q[1:] * q[:-1]
            sd[i] += (both * np.diff(chain, axis=0) ** 2).sum(axis=0)
            pairs[i] += both.sum(axis=0)
        previous = (values[-1:], np.ones((1, points)), quiet[-1:])
    R = int(sum(r.size for r in rev))
    if R < 2:
        raise InputError(f"{R} whole revolution(s) in the recording; the estimate needs at least 2",
                         source=record.source)
    for axis, sw in zip(axes, swing):
        refuse_dead_channel(axis, float(sw), 2.0 * math.pi * float(np.mean(np.concatenate(rate))), geometry,
                            record.source)
    use = 0
    if hits is not None:
        arrivals_s, quiet_s = hits
        if count[1].min() < 2:
            warnings.warn(f"{record.source}: {arrivals_s.size} cleat hits (hall channel): their ringing "
                          f"({quiet_s:.3g} s after each) leaves some angles without 2 quiet revolutions, so the hits "
                          "stay in the averaged profile and bias the estimate", RuntimeWarning, stacklevel=2)
        else:
            use = 1
            warnings.warn(f"{record.source}: {arrivals_s.size} cleat hits (hall channel): the {quiet_s:.3g} s after "
                          f"each ({100 * QUIET_SHARE:g} % of the drum period, what `ringfit cleat` leaves out of "
                          "its baseline) "
                          f"are left out of the averaged profile ({100 * (1 - count[1].mean() / R):.0f} % of its "
                          "samples); the per-revolution estimates keep them (their cleat_share says how much)",
                          RuntimeWarning, stacklevel=2)
    s1, s2, sd, count, pairs = s1[use], s2[use], sd[use], count[use], pairs[use]
    mean = s1 / count
    spread = np.sqrt(np.clip((s2 - count * mean**2) / np.maximum(count - 1, 1), 0.0, None))
    # noise of one revolution from successive differences: blind to a load that changes slowly or in steps; where
    # no two successive revolutions are both quiet at an angle (a cleat hit every ~2 revolutions), their spread
    noise = np.where(pairs >= 1, np.sqrt(sd / (2 * np.maximum(pairs, 1))), spread)
    rate = np.concatenate(rate)
    from ringfit.targets.faults import sample_rate_note

    note = sample_rate_note(float(np.mean(rate)), record.fs_hz, dict(record.condition))
    if note:
        warnings.warn(f"{record.source}: {note}", RuntimeWarning, stacklevel=2)
    elif record.has_encoder and geometry is not None:
        # the stated speed against the encoder's rotation for this tyre's radius (ringfit.io.conditions); the
        # encoder's rate is what the estimate uses
        from ringfit.io.conditions import rotation_speed_conflict

        clash = rotation_speed_conflict({"rotation_hz": float(np.mean(rate)),
                                         "speed_kmh": record.condition.get("speed_kmh")},
                                        float(geometry.outer_radius))
        if clash:
            warnings.warn(f"{record.source}: the encoder's {clash}; "
                          "the encoder's rate is used", RuntimeWarning, stacklevel=2)
    cond = {k: float(record.condition[k]) for k in ("speed_kmh", "pressure_bar", "drum_diameter_m")
            if record.condition.get(k) is not None}
    cond.update(revolutions=R, sample_rate_hz=float(record.fs_hz), rotation_hz=float(np.mean(rate)),
                **({} if tangential else {"missing_axes": ["tangential"]}))
    angle = grid_angles_deg(points)
    mean_t = t1[use] / count if tangential else np.zeros(points)
    # the interpolation's gain (docs/physics.md §10 *the acquisition's gain*): its modulus is the model's response,
    # its phase (O(θ³), where the grid points sit at one fraction between samples) is turned back out of the data
    every = interpolation_response(fractions, np.arange(1, points // 2 + 1))  # harmonics 1 … M/2
    gain = every[1:k_max]  # 2 … k_max
    turn = np.conj(gain) / np.abs(gain)
    mean, mean_t = _turned(mean, every), _turned(mean_t, every)
    profile = Profile(angle, mean, mean_t, condition=cond, source=str(record.source),
                      extra={"acc_radial_spread_ms2": np.array([repr(float(x)) for x in spread], dtype=object)})
    return RecordingRevolutions(rows=amplitude_rows(np.concatenate(rows) * turn), revolution=np.concatenate(rev),
                                t_s=np.concatenate(t_s),
                                rotation_hz=rate, profile=profile, response=np.abs(gain), k_max=k_max,
                                noise=noise / np.sqrt(count), rotation_source=source,
                                cleat_share=None if hits is None else np.concatenate(hit),
                                rows_tangential=amplitude_rows(np.concatenate(rows_t) * turn) if tangential else None,
                                **({} if use == 0 else {"noise_source": "the quiet revolutions (cleat hits left out): "
                                    "their successive differences, or their spread where no two successive ones are "
                                    "quiet, / √(revolutions), in the fitted band"}))


def cleat_windows(record, *, progress: bool = False):
    """``(arrivals_s, quiet_s)`` of a recording with a cleat trigger (hall channel): the arrival times [s from the
    first sample] and how long after each its ringing spoils the reading (:data:`ringfit.targets.cleat.QUIET_SHARE`
    of the drum period, what ``ringfit cleat`` leaves out by default); None without a hall channel."""
    if not getattr(record, "has_hall", False):
        return None
    from ringfit.targets.cleat import detect_cleat_arrivals

    arrivals = detect_cleat_arrivals(record, progress=progress)
    return np.asarray(arrivals.sample, dtype=np.float64) / float(record.fs_hz), QUIET_SHARE * float(arrivals.interval_s)


def _quiet(block, points: int, arrivals_s: np.ndarray, quiet_s: float) -> np.ndarray:
    """``(r, M)``: True where a revolution's grid angle was read outside every cleat hit's ringing window (and
    before the first hit). Grid angle j of a revolution is read at about t_mid + (j/M − ½)/rate (its angle is
    linear in time over one revolution)."""
    j = np.arange(points) / points - 0.5
    t = block.t_s[:, None] + j[None, :] / block.rotation_hz[:, None]
    k = np.searchsorted(arrivals_s, t, side="right") - 1
    tau = np.where(k >= 0, t - arrivals_s[np.maximum(k, 0)], np.inf)
    return tau >= quiet_s


def estimate_revolutions(data: RecordingRevolutions, reference: LoadEstimate, ring: RingParams, *,
                         settings: EstimateSettings = EstimateSettings(), batch: int = REVOLUTION_BATCH,
                         mode: RevolutionMode = "batch", progress: bool = False) -> RevolutionEstimates:
    """Load and patch for every whole revolution (from :func:`recording_revolutions`).

    Each revolution's harmonics 2…k_max are fitted for the load, the gain and the angle offset,
    with the high-pass corner, tilt and k_trd fixed at ``reference`` (the fit to the averaged
    profile; the gain is free because the averaged profile of a recording whose load changes is not
    the profile of one load, and a gain fixed there would bias every revolution) and Ω from the
    encoder per revolution. Revolutions go ``batch`` at a time to
    :func:`ringfit.fit.engine.least_squares_batch` (one compilation):

    - ``mode="batch"`` (default): each batch vmapped, every fit warm-started from the previous
      batch's last revolution (on a CPU, batches of 16 are ~20 % faster than the chain: the small
      matrix work vectorises across the batch, and Gauss–Newton takes 3–4 steps in every fit).
    - ``mode="chain"``: in order, each fit warm-started from the previous revolution's, the whole
      batch in one compiled ``lax.scan``; each batch continues from the previous batch's last fit.

    (Fitting stretches of the recording in parallel threads deadlocked XLA's CPU runtime here:
    one thread; on a CPU the batches run at ~600 revolutions per second.)

    Each fit is undamped Gauss–Newton (``method="gauss_newton"`` of the engine: from a neighbour's
    optimum it stops after 3–4 steps); a fit that does not settle is redone alone with
    Levenberg–Marquardt from the reference. The first batch is fitted twice: its residual spectrum, averaged over its revolutions, weights
    every fit (coloured noise, as in :func:`estimate_load`). A smaller contact window
    (``settings.revolution_window_deg``, widened to 1.3 × the reference patch) makes each solve
    cheaper; a batch in which a patch comes within 1.5° of it is refitted with ``settings.window_deg``.

    **Returns:** :class:`RevolutionEstimates`.
    """
    from tqdm import tqdm

    if mode not in get_args(RevolutionMode):
        raise ValueError(f"mode={mode!r}; expected {' or '.join(map(repr, get_args(RevolutionMode)))}")
    fit = reference.fit
    k_max = data.k_max
    if k_max != reference.k_max:
        raise ValueError("the reference estimate was fitted to other harmonics")
    K = k_max - 1
    geometry = fit.problem.data.geometry
    half = max(abs(reference.patch["leading_deg"]), abs(reference.patch["trailing_deg"]))
    window = float(min(settings.window_deg, max(settings.revolution_window_deg, 1.3 * half)))
    drum = reference.drum_diameter_m
    response = np.asarray(data.response, dtype=np.float64)
    template = EstimateArrays(geometry=geometry, ring=ring, omega=np.ones(1), roads=flat_or_drum(drum, 1),
                              response=response[None], measured=np.zeros((1, 2 * K)), weight=np.ones((1, 2 * K)))
    problems = {window: estimate_problem(template, dataclasses.replace(settings, window_deg=window),
                                         k_max),
                settings.window_deg: estimate_problem(template, settings, k_max)}
    free = (LOAD, GAIN, ANGLE_OFFSET)
    rows_all, omega_all = data.rows, 2 * math.pi * data.rotation_hz
    R = rows_all.shape[0]
    fixed = jax.tree.map(lambda x: np.broadcast_to(np.asarray(x), (batch,) + np.shape(x)).copy(),
                         (as_traced(geometry), as_traced(ring), flat_or_drum(drum, 1), response[None]))

    def _arrays(take, weight):
        geo, rng, roads, resp = fixed
        return EstimateArrays(geometry=geo, ring=rng, omega=omega_all[take][:, None], roads=roads, response=resp,
                              measured=rows_all[take][:, None], weight=np.broadcast_to(weight, (batch, 1, 2 * K)))

    def solve(start, theta, weight, win):
        """Fit revolutions start … start + batch − 1 (the last batch repeats its last revolution)."""
        take = np.minimum(np.arange(start, start + batch), R - 1)
        return least_squares_batch(problems[win], theta, free, _arrays(take, weight), max_steps=REVOLUTION_MAX_STEPS,
                                   rtol=REVOLUTION_TOL, atol=REVOLUTION_TOL, warm_start=mode == "chain",
                                   method="gauss_newton"), take

    def fit_batch(start, theta, weight):
        res, take = solve(start, theta, weight, window)
        patch = reference.curves.patch_at(res.values(LOAD))
        win = window
        if window < settings.window_deg and np.any(np.maximum(np.abs(patch["leading_deg"]),
                                                              np.abs(patch["trailing_deg"])) > window - 1.5):
            win = settings.window_deg
            res, take = solve(start, res.theta[0] if mode == "chain" else res.theta, weight, win)
        n = min(batch, R - start)
        for b in np.flatnonzero(~(res.converged[:n] & np.all(np.isfinite(res.theta[:n]), axis=1))):
            # Gauss–Newton did not settle: Levenberg–Marquardt from the reference, this revolution alone (the
            # averaged profile's compiled fit: same model, free set padded to its size)
            alone = dataclasses.replace(problems[settings.window_deg],
                                        data=as_traced(jax.tree.map(lambda x: x[b], _arrays(take, weight))))
            one = least_squares(alone, theta_ref, free, max_steps=settings.max_steps, rtol=settings.rtol,
                                atol=settings.atol, pad_to=len(fit.names))
            res.theta[b], res.status[b], res.iterations[b] = one.theta, one.status, one.iterations
            res.covariance_log[b], res.stderr[b] = one.covariance_log, [one.stderr[k] for k in free]
            res.residuals[b], res.chi2_raw[b] = one.residuals, one.extra["chi2_raw"]
            res.sigma_scale[b], res.aux[b] = one.extra["sigma_scale"], np.asarray(one.extra["aux"])
            res.at_bound[b] = [k in one.extra["at_bound"] for k in free]
        return res, take

    # weights from the first batch's residual spectrum
    theta_ref = np.asarray(fit.theta, dtype=np.float64).copy()
    first, take = fit_batch(0, theta_ref, np.ones(2 * K))
    n0 = min(batch, R)
    # the profile block's noise spectrum (docs/physics.md §11 *profiles*), its power pooled over the first batch's
    # revolutions (each fit took len(free) of its 2K rows); it gives the weights' shape, each revolution's own
    # residual their scale (σ "estimate": the noise level may change along a recording). Each revolution's
    # residual enters divided by its own RMS, so that one read too strong (an outlier, rejected below) does not
    # shape every revolution's weights
    resid0 = first.aux[:n0, 0] - rows_all[take[:n0]]
    resid0 = resid0 / np.maximum(np.sqrt(np.mean(resid0**2, axis=1, keepdims=True)), 1e-300)
    sigma = noise_from_residual(np.sqrt(np.mean(resid0**2, axis=0)), np.full(2 * K, len(free) / (2 * K)), k_min=2,
                                series=n0)
    weight = (1.0 / sigma) / np.mean(1.0 / sigma)

    starts = np.arange(0, R, batch)
    bar = tqdm(total=R, unit="rev", disable=not progress, desc="per-revolution fits")
    results = {}
    theta = theta_ref
    for start in starts:
        res, _ = fit_batch(int(start), theta, weight)
        n = min(batch, R - int(start))
        # a revolution whose load or gain sits on its bound did not find an optimum inside the model's range
        on_bound = res.at_bound[:n][:, [free.index(LOAD), free.index(GAIN)]].any(axis=1)
        ok = res.converged[:n] & ~on_bound & np.all(np.isfinite(res.theta[:n]), axis=1)
        if ok.any():
            theta = res.theta[np.flatnonzero(ok)[-1]].copy()
        results[int(start)] = (res, n, ok)
        bar.update(n)
    bar.close()
    parts = []
    for start in starts:
        res, n, ok = results[int(start)]
        lo, hi = res.interval(LOAD)
        resid = res.aux[:n, 0] - rows_all[start:start + n]
        parts.append(dict(load=res.values(LOAD)[:n], lo=lo[:n], hi=hi[:n], gain=res.values(GAIN)[:n],
                          offset=np.degrees(res.values(ANGLE_OFFSET)[:n]),
                          rms=np.sqrt(0.5 * np.sum(resid[:, :K] ** 2 + resid[:, K:] ** 2, axis=1)), ok=ok,
                          iterations=res.iterations[:n], scale=np.asarray(res.sigma_scale[:n], dtype=np.float64)))
    cat = {key: np.concatenate([r[key] for r in parts]) for key in parts[0]}
    ratio, outlier = residual_outliers(cat["scale"], cat["ok"], dof=2 * K - len(free))
    cat["ok"] = cat["ok"] & ~outlier
    spacing = edge_peaks(rows_all[:, :K] + 1j * rows_all[:, K:], 2)[:, 2]
    return RevolutionEstimates(
        revolution=data.revolution, t_s=data.t_s, rotation_hz=data.rotation_hz, load_n=cat["load"], lo=cat["lo"],
        hi=cat["hi"], length_mm=np.asarray(reference.curves.patch_at(cat["load"])["length_mm"]), gain=cat["gain"],
        angle_offset_deg=cat["offset"], rms=cat["rms"], converged=cat["ok"], iterations=cat["iterations"],
        feature_load_n=reference.curves.load_from_spacing(spacing), window_deg=window, cleat_share=data.cleat_share,
        residual_ratio=ratio, outlier=outlier)


def residual_outliers(scale: np.ndarray, fitted: np.ndarray, dof: int, z: float = OUTLIER_Z,
                      neighbours: int = OUTLIER_NEIGHBOURS) -> tuple[np.ndarray, np.ndarray]:
    """The per-revolution outlier rule (docs/physics.md §10): which revolutions the recording does not vouch for.

    ``scale`` ``(R,)``: each revolution fit's residual scale s_r (its weighted residual's RMS per degree of
    freedom; the weights' shape is the recording's, so s_r reads the revolution's own noise level); ``fitted``
    ``(R,)``: the fits that settled (only they set the reference); ``dof``: rows − free parameters of one fit.

    d_r = ln s_r − median of ln s over the settled fits among revolutions r ± ``neighbours`` (the noise may drift
    along a recording: speed, road). Its spread is estimated robustly over the recording, 1.4826 × median |d|,
    and never taken below 1/√(2ν), ln s's own sampling spread for Gaussian noise with ν = ``dof``; a revolution
    with |d_r| above ``z`` such spreads is an outlier (a sensor that read it too strong or too weak, a burst, a
    revolution the steady model cannot describe). With 5 spreads a Gaussian recording would lose a revolution with
    probability ~6e-7 were the median and the spread known; estimated from 40 revolutions, the loss measured on
    simulated nulls (tests/test_estimate.py) is 0–3e-5 for Gaussian noise, a noise level that doubles along the
    recording included, and 4e-4 where each revolution's misfit also varies by a log-normal 25 %. A revolution
    read 4× too strong or a tenth, or with a noise burst 2.5× the recording's, is caught in ≥ 95–99 % of cases.

    **Returns:** ``(ratio, outlier)``: s_r over its neighbours' median ``(R,)`` (NaN where s_r is not finite) and
    the rejected revolutions ``(R,)`` bool. Fewer than three settled fits: no reference, nothing rejected.
    """
    scale = np.asarray(scale, dtype=np.float64)
    good = np.asarray(fitted, bool) & np.isfinite(scale) & (scale > 0)
    R = scale.size
    ratio = np.full(R, np.nan)
    outlier = np.zeros(R, bool)
    if good.sum() < 3:
        return ratio, outlier
    ln = np.where(good, np.log(np.where(good, scale, 1.0)), np.nan)
    padded = np.pad(ln, neighbours, constant_values=np.nan)
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * neighbours + 1)  # (R, 2·neighbours + 1)
    with warnings.catch_warnings():  # a window without a settled fit: the recording's median instead
        warnings.simplefilter("ignore", RuntimeWarning)
        ref = np.nanmedian(windows, axis=1)
    ref = np.where(np.isfinite(ref), ref, np.nanmedian(ln))
    d = np.where(good, ln - ref, np.nan)
    spread = max(1.4826 * float(np.median(np.abs(d[good]))), 1.0 / math.sqrt(2.0 * max(int(dof), 1)))
    ratio[good] = np.exp(d[good])
    outlier[good] = np.abs(d[good]) > z * spread
    return ratio, outlier


def estimate_recording(record, geometry: TyreGeometry, ring: RingParams, *,
                       settings: EstimateSettings = EstimateSettings(), k_tread_in_file: bool = True,
                       per_revolution: bool = True, batch: int = REVOLUTION_BATCH, mode: RevolutionMode = "batch",
                       progress: bool = False, ring_covariance=None, laws=None):
    """The averaged and the per-revolution estimates of a continuous recording (one pass over it).

    The averaged profile (:func:`recording_revolutions`) is estimated like any profile
    (:func:`estimate_load`; Ω the encoder's mean rate, noise the revolution spread); its nuisances then
    serve every revolution (:func:`estimate_revolutions`). ``ring_covariance`` (the tyre file's) is propagated into
    the averaged estimate's interval (:func:`~ringfit.fit.estimate.load.estimate_load`); the per-revolution
    intervals stay statistical (the ring's error is common to every revolution of one recording).

    **Returns:** ``(LoadEstimate, RevolutionEstimates or None)``.
    """
    data = recording_revolutions(record, k_max=settings.k_max, progress=progress, geometry=geometry)
    rate = float(np.mean(data.rotation_hz))
    reference = estimate_load(data.profile, geometry, ring, settings=settings, k_tread_in_file=k_tread_in_file,
                              omega=2 * math.pi * rate, omega_source=data.rotation_source,
                              response=data.response, noise_per_angle=data.noise,
                              noise_source=data.noise_source,
                              ring_covariance=ring_covariance, laws=laws)
    revs = None
    if per_revolution:
        revs = estimate_revolutions(data, reference, ring, settings=settings, batch=batch, mode=mode,
                                    progress=progress)
    return reference, revs
