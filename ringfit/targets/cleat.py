"""Cleat tests: the tyre's response in the plane of sensor angle × time since the cleat's arrival.

One co-rotating sensor sees each cleat hit from one place only, but the drum
circumference is not a multiple of the tyre's, so every pass starts with the
sensor somewhere else. Stacking the passes fills the (φ, τ) plane (the
source's §4.2, figure 23):

1. :func:`detect_cleat_arrivals` — rising edges of the hall channel (Schmitt
   trigger at 40/60 % of its range, the 50 % crossing interpolated between
   samples) plus the hall-to-tyre delay give the arrival times; the sensor
   angle at each arrival comes from the encoder.
2. :func:`angle_time_field` — every sample gets τ = time since the latest
   arrival; it is binned by sensor angle (``sectors`` equal sectors, sector j
   centred on −180 + 360 (j + ½)/S) and by τ (``time_step``, default the
   sample interval); the no-cleat reading at the same angle is subtracted
   sample by sample (a :class:`~ringfit.targets.rolling_profile.RollingProfile`
   or docs/formats.md §3 profile, or by default the record's own samples long after
   each hit), and the samples sharing a bin are averaged. One pass over the
   recording in chunks with ``np.add.at``: memory is bounded by the field,
   not by the recording.
3. :func:`coverage_summary` / :func:`passes_for_full_coverage` — how well the
   passes fill the plane, and how many are needed given the circumference ratio.

The field lives in the fixed (axle) frame: sector j is a place around the
wheel measured from the patch centre, so its time series show the waves at
their fixed-frame (Doppler-shifted) frequencies (docs/physics.md §3.3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.continuous import DEFAULT_CHUNK, ContinuousRecord
from ringfit.io.files import load_npz
from ringfit.io.record_types import Axis


# --------------------------------------------------------------------------- arrivals


@dataclass
class CleatArrivals:
    """Cleat arrivals at the tyre.

    **Fields** (shape ``(K,)``): ``sample`` fractional sample index of each
    arrival; ``time_s`` = sample / fs [s]; ``sensor_angle_deg`` sensor angle φ
    at the arrival, wrapped to [−180, 180) [deg]. ``fs_hz`` the sample rate.
    """

    sample: np.ndarray
    time_s: np.ndarray
    sensor_angle_deg: np.ndarray
    fs_hz: float

    def __len__(self):
        return self.sample.shape[0]

    @property
    def interval_s(self) -> float:
        """Median time between arrivals (one drum revolution) [s]."""
        if len(self) < 2:
            raise InputError(f"{len(self)} cleat arrival(s); need at least 2 to know the drum period")
        return float(np.median(np.diff(self.time_s)))

    def angle_step_deg(self) -> float:
        """Median advance of the sensor angle from one arrival to the next, wrapped to [0, 360) [deg]."""
        return float(np.median(np.diff(np.unwrap(np.radians(self.sensor_angle_deg)))) % (2 * np.pi) * 180 / np.pi)


#: The share of the drum period after each cleat hit whose readings its ringing spoils: left out of a baseline
#: profile (:func:`angle_time_field`'s default ``quiet_after_s``) and of ``ringfit estimate``'s averaged profile.
QUIET_SHARE = 0.7


def detect_cleat_arrivals(
    record: ContinuousRecord,
    *,
    threshold: tuple[float, float] | None = None,
    chunk: int = DEFAULT_CHUNK,
    progress: bool = False,
) -> CleatArrivals:
    """Cleat arrivals from the hall channel's rising edges.

    **Arguments:**

    - ``record``: a continuous record with ``hall`` (and an encoder for the angles).
    - ``threshold``: (low, high) Schmitt levels; default 40 % and 60 % of the
      channel's range (one extra pass over the hall channel).

    **Returns:** :class:`CleatArrivals`, arrival = 50 % crossing + ``hall_delay_s``.

    **Raises:** :class:`InputError` without a hall channel, a flat hall
    channel, or fewer than 2 edges.
    """
    if not record.has_hall:
        raise InputError("no 'hall' channel; a cleat test needs the hall sensor's cleat pulses", source=record.source)
    from tqdm import tqdm

    if threshold is None:
        lo_v, hi_v = np.inf, -np.inf
        for i0 in range(0, record.samples, chunk):
            h = record.read("hall", i0, i0 + chunk)
            lo_v, hi_v = min(lo_v, float(h.min())), max(hi_v, float(h.max()))
        if not hi_v > lo_v:
            raise InputError(f"key 'hall' is flat ({lo_v:g}); no cleat pulses", source=record.source)
        low, high = lo_v + 0.4 * (hi_v - lo_v), lo_v + 0.6 * (hi_v - lo_v)
    else:
        low, high = (float(x) for x in threshold)
        if not high > low:
            raise InputError(f"hall threshold {threshold}: expected (low, high) with high > low")
    mid = 0.5 * (low + high)

    # The arrival angles come from the encoder on the way, from a short window of
    # (sample, angle) pairs every `step` samples (memory independent of the
    # recording's length): an arrival is resolved once the walk has passed it.
    step = 64
    delay = record.hall_delay_s * record.fs_hz
    keep_back = int(math.ceil(max(0.0, -delay))) + 2 * step  # how far back an arrival can lie
    win_i, win_a = np.empty(0), np.empty(0)
    crossings, pending, angles = [], [], []
    armed = None  # True once the level has been below `low` since the last trigger
    prev = None
    bar = tqdm(total=record.samples, unit="sample", unit_scale=True, disable=not progress, desc="hall")
    for ch in record.chunks(chunk, acc=False):
        h = ch.hall
        state = np.zeros(h.size, dtype=np.int8)
        state[h > high] = 1
        state[h < low] = -1
        ev = np.flatnonzero(state)
        if ev.size:
            s = state[ev]
            before = np.concatenate([[(-1 if armed else 1) if armed is not None else 0], s[:-1]])
            trig = ev[(s == 1) & (before == -1)]
            armed = bool(s[-1] == -1)
            for i in trig:  # few per chunk: walk back to the last sample below the 50 % level
                j = int(i)
                while j > 0 and h[j - 1] >= mid and i - j < 16:
                    j -= 1
                x1 = h[j]
                x0 = h[j - 1] if j > 0 else prev
                if x0 is not None and x0 < mid <= x1:
                    c = ch.start + j - 1 + (mid - x0) / (x1 - x0)
                else:
                    c = float(ch.start + j)
                crossings.append(c)
                pending.append(c + delay)
        prev = float(h[-1])
        if ch.angle_deg is not None:
            at = np.append(np.arange(0, len(ch), step), len(ch) - 1)
            win_i = np.concatenate([win_i, ch.start + at.astype(np.float64)])
            win_a = np.concatenate([win_a, ch.angle_deg[at]])  # fancy indexing: a copy, not a view
            ready = 0
            while ready < len(pending) and pending[ready] <= ch.stop - 1:
                ready += 1
            if ready:
                angles.extend(np.interp(pending[:ready], win_i, win_a).tolist())
                del pending[:ready]
            old = win_i < ch.stop - 1 - keep_back
            win_i, win_a = win_i[~old], win_a[~old]
        bar.update(len(ch))
    bar.close()
    if len(crossings) < 2:
        raise InputError(f"found {len(crossings)} cleat pulse(s) in 'hall'; need at least 2", source=record.source)
    sample = np.asarray(crossings) + delay
    if record.has_encoder:
        if pending:  # arrivals after the last sample: the last angle (as np.interp clamps)
            angles.extend(np.interp(pending, win_i, win_a).tolist())
        angle = (np.asarray(angles) + 180.0) % 360.0 - 180.0
    else:
        angle = np.full(sample.shape, np.nan)
    found = CleatArrivals(sample=sample, time_s=sample / record.fs_hz, sensor_angle_deg=angle, fs_hz=record.fs_hz)
    from ringfit.targets.faults import trigger_rate_note

    note = trigger_rate_note(found.interval_s, record.fs_hz, dict(record.condition))
    if note:
        import warnings

        warnings.warn(f"{record.source}: {note}", RuntimeWarning, stacklevel=2)
    return found


def time_since_arrival(sample_index, arrivals_sample: np.ndarray, fs_hz: float) -> np.ndarray:
    """τ [s] of each sample since the latest arrival at or before it; −1 before the first arrival."""
    idx = np.asarray(sample_index, dtype=np.float64)
    k = np.searchsorted(arrivals_sample, idx, side="right") - 1
    return np.where(k >= 0, (idx - arrivals_sample[np.maximum(k, 0)]) / fs_hz, -1.0)


# --------------------------------------------------------------------------- the field


@dataclass
class AngleTimeField:
    """Average cleat response on the (sensor angle × time since arrival) plane.

    **Fields:**

    - ``sector_deg``: (S,) sector centres φ [deg] from the patch centre.
    - ``tau_s``: (T,) start of each time bin [s]; ``time_step_s`` its width.
    - ``axes``: axis names of ``mean``.
    - ``mean``: (axes, S, T) average of the samples in each bin, no-cleat
      reading subtracted [m/s²]; NaN where a bin got no sample.
    - ``spread``: (axes, S, T) standard deviation of the samples in each bin [m/s²] (NaN below 2).
    - ``count``: (S, T) samples per bin.
    - ``phi_mean_deg``, ``tau_mean_s``: (S, T) mean coordinates of the samples in each bin.
    - ``arrivals``: the :class:`CleatArrivals` used; ``passes``: arrivals that contributed.
    - ``rotation_hz``: wheel rotation rate from the encoder [Hz]; ``fs_hz``: sample rate.
    - ``baseline``: what was subtracted (text); ``condition``: the record's condition.
    """

    sector_deg: np.ndarray
    tau_s: np.ndarray
    time_step_s: float
    axes: tuple
    mean: np.ndarray
    spread: np.ndarray
    count: np.ndarray
    phi_mean_deg: np.ndarray
    tau_mean_s: np.ndarray
    arrivals: CleatArrivals
    passes: int
    rotation_hz: float
    fs_hz: float
    baseline: str = ""
    condition: dict = field(default_factory=dict)

    @property
    def sectors(self) -> int:
        return self.sector_deg.shape[0]

    def channel(self, axis: Axis = "radial") -> np.ndarray:
        """(S, T) field of one axis [m/s²]."""
        if axis not in self.axes:
            raise InputError(f"field has no '{axis}' axis (have: {', '.join(self.axes)})")
        return self.mean[self.axes.index(axis)]

    def coverage(self) -> dict:
        """Coverage of the plane (see :func:`coverage_summary`)."""
        return coverage_summary(self)

    def save(self, path, *, overwrite: bool = False, extra: dict | None = None) -> Path:
        """Write the field as an npz (keys below; ``extra`` adds more, e.g. identified modes)."""
        from ringfit.io.files import atomic_write, check_output_path

        path = check_output_path(path, overwrite=overwrite)
        arrays = {
            "kind": np.array("angle_time_field"),
            "sector_deg": self.sector_deg,
            "tau_s": self.tau_s,
            "time_step_s": np.float64(self.time_step_s),
            "axes": np.array(self.axes),
            "mean": self.mean,
            "spread": self.spread,
            "count": self.count,
            "phi_mean_deg": self.phi_mean_deg,
            "tau_mean_s": self.tau_mean_s,
            "arrival_sample": self.arrivals.sample,
            "arrival_angle_deg": self.arrivals.sensor_angle_deg,
            "passes": np.int64(self.passes),
            "rotation_hz": np.float64(self.rotation_hz),
            "fs_hz": np.float64(self.fs_hz),
            "baseline": np.array(self.baseline),
        }
        for k in ("speed_kmh", "load_n", "pressure_bar", "drum_diameter_m"):
            if self.condition.get(k) is not None:
                arrays[k] = np.float64(self.condition[k])
        arrays.update(extra or {})

        def write(tmp):
            with open(tmp, "wb") as f:
                np.savez(f, **arrays)

        atomic_write(path, write)
        return path


def load_field(path) -> AngleTimeField:
    """Read a field written by :meth:`AngleTimeField.save`; InputError naming file and key otherwise."""
    path = Path(path)
    z = load_npz(path)
    if "kind" not in z or str(z["kind"]) != "angle_time_field":
        raise InputError("not an angle-time field (key 'kind' != 'angle_time_field')", source=path)
    need = ("sector_deg", "tau_s", "time_step_s", "axes", "mean", "spread", "count", "phi_mean_deg",
            "tau_mean_s", "arrival_sample", "arrival_angle_deg", "passes", "rotation_hz", "fs_hz")
    for k in need:
        if k not in z:
            raise InputError(f"missing key '{k}'", source=path)
    fs = float(z["fs_hz"])
    arr = CleatArrivals(z["arrival_sample"], z["arrival_sample"] / fs, z["arrival_angle_deg"], fs)
    cond = {k: float(z[k]) for k in ("speed_kmh", "load_n", "pressure_bar", "drum_diameter_m") if k in z}
    return AngleTimeField(
        sector_deg=z["sector_deg"], tau_s=z["tau_s"], time_step_s=float(z["time_step_s"]),
        axes=tuple(str(a) for a in z["axes"]), mean=z["mean"], spread=z["spread"], count=z["count"],
        phi_mean_deg=z["phi_mean_deg"], tau_mean_s=z["tau_mean_s"], arrivals=arr, passes=int(z["passes"]),
        rotation_hz=float(z["rotation_hz"]), fs_hz=fs, baseline=str(z["baseline"]) if "baseline" in z else "",
        condition=cond,
    )


def _baseline_functions(baseline, axes):
    """Per-axis functions φ [deg] → no-cleat reading, from a RollingProfile or a docs/formats.md §3 Profile."""
    from ringfit.targets.rolling_profile import RollingProfile, periodic_interpolator

    funcs = []
    for a in axes:
        if isinstance(baseline, RollingProfile):
            funcs.append(baseline.interpolator(a) if a in baseline.axes else None)
        else:  # ringfit.io.profiles.Profile
            col = {"radial": "acc_radial_ms2", "tangential": "acc_tangential_ms2"}.get(a)
            if col is None:
                funcs.append(None)
                continue
            from ringfit.io.profiles import resample_profile

            m = max(256, 1 << int(math.ceil(math.log2(len(baseline.angle_deg)))))
            grid = resample_profile(baseline, m)[0 if a == "radial" else 1]
            funcs.append(periodic_interpolator(grid))
    return funcs


class _BinSums:
    """Running sums over the (sector × time-bin) plane; memory: the field only.

    Samples are added with ``np.add.at`` (no full-size temporary per chunk);
    :meth:`finish` turns the sums into means in place, a block of bins at a time.
    """

    BLOCK = 1 << 14  # bins per finishing step (its temporaries: a few × 128 kB)

    def __init__(self, na: int, sectors: int, n_t: int):
        self.sectors, self.n_t = sectors, n_t
        n = sectors * n_t
        self.s1 = np.zeros((na, n))  # Σ x
        self.s2 = np.zeros((na, n))  # Σ x²
        self.cnt = np.zeros(n, dtype=np.int64)
        self.sphi = np.zeros(n)  # Σ position inside the sector (0..1)
        self.stau = np.zeros(n)  # Σ τ

    def add_chunk(self, ch, arr, fs, dt, rows, funcs, used) -> None:
        """Bin the samples of chunk ``ch`` that lie within the field's duration after an arrival."""
        idx = np.arange(ch.start, ch.stop, dtype=np.float64)
        k = np.searchsorted(arr, idx, side="right") - 1
        tau = (idx - arr[np.maximum(k, 0)]) / fs
        m = np.floor(tau / dt).astype(np.int64)
        ok = (k >= 0) & (m >= 0) & (m < self.n_t)
        if not ok.any():
            return
        used[np.unique(k[ok])] = True
        phi, tau, m = ch.angle_deg[ok], tau[ok], m[ok]
        pos = (phi + 180.0) / (360.0 / self.sectors)
        sec = np.floor(pos)
        pos -= sec  # position inside the sector, 0..1
        flat = (sec.astype(np.int64) % self.sectors) * self.n_t + m
        np.add.at(self.cnt, flat, 1)
        np.add.at(self.sphi, flat, pos)
        np.add.at(self.stau, flat, tau)
        for i, r in enumerate(rows):
            x = ch.acc[r][ok]
            if funcs[i] is not None:
                x -= funcs[i](phi)
            np.add.at(self.s1[i], flat, x)
            x *= x
            np.add.at(self.s2[i], flat, x)

    def finish(self):
        """(mean, spread (axes, S, T); count, phi_mean_deg, tau_mean_s (S, T)), computed in place."""
        s1, s2, cnt, sphi, stau = self.s1, self.s2, self.cnt, self.sphi, self.stau
        with np.errstate(invalid="ignore", divide="ignore"):
            for j0 in range(0, cnt.size, self.BLOCK):
                sl = slice(j0, j0 + self.BLOCK)
                c = cnt[sl].astype(np.float64)
                for i in range(s1.shape[0]):
                    mean, sq = s1[i, sl], s2[i, sl]
                    mean /= c  # empty bins: 0/0 = NaN
                    sq -= c * mean * mean
                    sq /= c - 1.0
                    np.clip(sq, 0.0, None, out=sq)
                    np.sqrt(sq, out=sq)
                    sq[c < 2] = np.nan
                sphi[sl] /= c
                stau[sl] /= c
        S, T = self.sectors, self.n_t
        phi = sphi.reshape(S, T)
        phi += np.arange(S)[:, None]
        phi *= 360.0 / S
        phi -= 180.0
        na = s1.shape[0]
        return s1.reshape(na, S, T), s2.reshape(na, S, T), cnt.reshape(S, T), phi, stau.reshape(S, T)


def angle_time_field(
    record: ContinuousRecord,
    *,
    sectors: int = 512,
    time_step_s: float | None = None,
    duration_s: float | None = None,
    baseline="auto",
    arrivals: CleatArrivals | None = None,
    axes=None,
    quiet_after_s: float | None = None,
    profile_points: int | None = None,
    chunk: int = DEFAULT_CHUNK,
    progress: bool = False,
) -> AngleTimeField:
    """Rebuild the cleat response on the (sensor angle × time since arrival) plane.

    **Arguments:**

    - ``record``: continuous record with encoder and hall.
    - ``sectors``: S equal sectors around the tyre (the source used 512).
    - ``time_step_s``: width of a time bin (default 1/fs, the source's choice).
    - ``duration_s``: time after each arrival that is binned (default: the
      median time between arrivals, i.e. until the next hit).
    - ``baseline``: the no-cleat reading subtracted at the same angle:
      ``"auto"`` — a profile from this record's samples at least
      ``quiet_after_s`` (default 70 % of the drum period) after each arrival;
      a :class:`~ringfit.targets.rolling_profile.RollingProfile` or docs/formats.md §3
      :class:`~ringfit.io.profiles.Profile` (e.g. from a no-cleat recording);
      or ``None`` (nothing subtracted).
    - ``arrivals``: reuse detected arrivals (default: detect them).
    - ``axes``: axes to rebuild (default all).
    - ``profile_points``: angle points of the ``"auto"`` baseline (default
      max(2048, 4·sectors), capped by the samples per revolution).

    **Returns:** :class:`AngleTimeField`.
    """
    from tqdm import tqdm

    from ringfit.targets.rolling_profile import rolling_profile

    if not record.has_encoder:
        raise InputError("no encoder channel; the field needs the sensor angle", source=record.source)
    sectors = int(sectors)
    if sectors < 4:
        raise InputError(f"sectors = {sectors}; expected at least 4")
    axes = tuple(record.axes if axes is None else axes)
    rows = [record.axis_index(a) for a in axes]
    fs = record.fs_hz
    if arrivals is None:
        arrivals = detect_cleat_arrivals(record, chunk=chunk, progress=progress)
    period = arrivals.interval_s
    duration = period if duration_s is None else float(duration_s)
    dt = 1.0 / fs if time_step_s is None else float(time_step_s)
    if not (dt > 0 and duration > dt):
        raise InputError(f"time step {dt:g} s and duration {duration:g} s: expected 0 < step < duration")
    n_t = int(math.ceil(duration / dt - 1e-9))

    label = "none"
    funcs = [None] * len(axes)
    if isinstance(baseline, str):
        if baseline != "auto":
            raise InputError(f"baseline {baseline!r}; expected 'auto', a profile or None")
        quiet = QUIET_SHARE * period if quiet_after_s is None else float(quiet_after_s)
        if quiet >= period:
            raise InputError(f"quiet_after_s = {quiet:g} s leaves no quiet samples (drum period {period:g} s)")
        rev_hz_guess = record.condition.get("rotation_hz")
        per_rev = fs / rev_hz_guess if rev_hz_guess else 4096
        points = profile_points or int(min(max(2048, 4 * sectors), 2 ** math.floor(math.log2(per_rev))))
        prof = rolling_profile(record, points=points, axes=axes, arrivals_samples=arrivals.sample,
                               quiet_after_s=quiet, chunk=chunk, progress=progress)
        funcs = _baseline_functions(prof, axes)
        label = f"auto: profile of this record, samples >= {quiet:.4g} s after each arrival, {points} points"
    elif baseline is not None:
        funcs = _baseline_functions(baseline, axes)
        label = f"given profile ({getattr(baseline, 'source', '') or type(baseline).__name__})"

    na = len(axes)
    sums = _BinSums(na, sectors, n_t)
    arr = arrivals.sample
    used = np.zeros(len(arr), dtype=bool)
    first = last = None
    bar = tqdm(total=record.samples, unit="sample", unit_scale=True, disable=not progress, desc="field")
    for ch in record.chunks(chunk):
        if first is None:
            first = float(ch.angle_deg[0])
        last = float(ch.angle_deg[-1])
        sums.add_chunk(ch, arr, fs, dt, rows, funcs, used)
        bar.update(len(ch))
    bar.close()
    mean, spread, count, phi_mean, tau_mean = sums.finish()
    width = 360.0 / sectors
    total_rev = (last - first) / 360.0
    if not abs(total_rev) >= 2:
        raise InputError(f"the encoder turns {total_rev:.2f} revolutions over the recording; a cleat field needs at "
                         "least 2 (a frozen or disconnected encoder?)", source=record.source)
    rotation_hz = total_rev / ((record.samples - 1) / fs)
    return AngleTimeField(
        sector_deg=-180.0 + width * (np.arange(sectors) + 0.5),
        tau_s=np.arange(n_t) * dt,
        time_step_s=dt,
        axes=axes,
        mean=mean,
        spread=spread,
        count=count,
        phi_mean_deg=phi_mean,
        tau_mean_s=tau_mean,
        arrivals=arrivals,
        passes=int(used.sum()),
        rotation_hz=float(rotation_hz),
        fs_hz=float(fs),
        baseline=label,
        condition=dict(record.condition),
    )


# --------------------------------------------------------------------------- coverage


def passes_for_full_coverage(arrival_angles_deg, sectors: int) -> int | None:
    """Fewest passes (in recording order) whose start angles leave no circular gap wider than a sector.

    When the largest gap between the sensor angles at the arrivals is below
    360/S, every sector is visited at every τ (each pass sweeps a line
    φ = φ_k + Ωτ through the plane). Returns None if all passes are not enough.
    """
    a = np.mod(np.asarray(arrival_angles_deg, dtype=np.float64), 360.0)
    width = 360.0 / sectors
    # doubling search, then bisection (the max gap only shrinks as passes are added)
    def max_gap(n):
        s = np.sort(a[:n])
        return float(np.max(np.diff(np.append(s, s[0] + 360.0))))

    if a.size == 0 or max_gap(a.size) >= width:
        return None
    lo, hi = 1, 1
    while max_gap(hi) >= width:
        lo, hi = hi, min(2 * hi, a.size)
    while lo < hi:
        mid = (lo + hi) // 2
        if max_gap(mid) < width:
            hi = mid
        else:
            lo = mid + 1
    return hi


def predicted_arrival_angles(circumference_ratio: float, passes: int, start_deg: float = 0.0) -> np.ndarray:
    """Sensor angle at each arrival for a drum/tyre circumference ratio (no slip, constant radii) [deg].

    Between two passes the tyre turns ``circumference_ratio`` revolutions, so
    the k-th arrival finds the sensor at start + 360·ratio·k (wrapped).
    """
    k = np.arange(int(passes))
    return (start_deg + 360.0 * circumference_ratio * k + 180.0) % 360.0 - 180.0


def coverage_summary(field: AngleTimeField) -> dict:
    """How the passes fill the (sector × time-bin) plane.

    **Returns** a dict: ``passes``, ``bins``, ``filled_fraction`` (bins with at
    least one sample), ``min_count``, ``median_count``, ``mean_count``,
    ``angle_step_deg`` (sensor advance per pass), ``passes_for_full_coverage``
    (from the measured arrival angles, :func:`passes_for_full_coverage`).
    """
    c = field.count
    return {
        "passes": int(field.passes),
        "bins": int(c.size),
        "filled_fraction": float((c > 0).mean()),
        "min_count": int(c.min()),
        "median_count": float(np.median(c)),
        "mean_count": float(c.mean()),
        "angle_step_deg": field.arrivals.angle_step_deg() if len(field.arrivals) > 1 else float("nan"),
        "passes_for_full_coverage": passes_for_full_coverage(field.arrivals.sensor_angle_deg, field.sectors),
    }


def coverage_points(record: ContinuousRecord, arrivals: CleatArrivals, passes: int, duration_s: float,
                    step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(φ [deg], τ [s]) of the samples of the first ``passes`` passes (every ``step``-th), for figure 23.

    Reads only the start of the recording.
    """
    passes = min(int(passes), len(arrivals))
    if passes < 1:
        raise InputError("no cleat passes to plot")
    stop = int(min(record.samples, math.ceil(arrivals.sample[passes - 1] + duration_s * record.fs_hz) + 1))
    start = int(max(0, math.floor(arrivals.sample[0])))
    phis, taus = [], []
    for ch in record.chunks(DEFAULT_CHUNK, stop=stop):
        idx = np.arange(ch.start, ch.start + len(ch), dtype=np.float64)
        tau = time_since_arrival(idx, arrivals.sample[:passes], record.fs_hz)
        ok = (idx >= start) & (tau >= 0) & (tau < duration_s)
        sel = np.flatnonzero(ok)[::step]
        phis.append((ch.angle_deg[sel] + 180.0) % 360.0 - 180.0)
        taus.append(tau[sel])
    return np.concatenate(phis), np.concatenate(taus)


def field_error(field: AngleTimeField, truth, axis: Axis = "radial", *, tau_min_s: float = 0.0,
                min_count: int = 1) -> dict:
    """Compare a field with a truth function ``truth(phi_deg, tau_s)`` at each bin's mean coordinates.

    **Returns** ``{"rms": …, "truth_rms": …, "relative": rms/truth_rms, "max": …, "bins": n}`` over
    bins with at least ``min_count`` samples and τ ≥ ``tau_min_s`` [m/s²].
    """
    x = field.channel(axis)
    ok = (field.count >= min_count) & (field.tau_mean_s >= tau_min_s) & np.isfinite(x)
    t = truth(field.phi_mean_deg[ok], field.tau_mean_s[ok])
    d = x[ok] - t
    rms = float(np.sqrt(np.mean(d**2)))
    trms = float(np.sqrt(np.mean(t**2)))
    return {"rms": rms, "truth_rms": trms, "relative": rms / trms if trms > 0 else float("inf"),
            "max": float(np.max(np.abs(d))), "bins": int(ok.sum())}
