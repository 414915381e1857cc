"""Rolling profiles from a continuous recording: per-revolution readings by sensor angle, averaged.

On a smooth drum or road every revolution reads the same (the source's figure
22), so the profile is the average over revolutions of the readings binned by
sensor angle φ, and the revolution-to-revolution spread is the noise estimate
that the rolling fit and the gap diagnosis weight by.

The recording is walked in chunks (bounded memory). For every revolution r
and angle bin j (``points`` bins centred on φ_j = −180 + 360 j/M, docs/formats.md §3)
the samples are averaged into x̄_rj; the profile is the mean of x̄_rj over
the revolutions that have samples in bin j, the spread their standard
deviation (ddof = 1). Samples within ``quiet_after_s`` of a cleat arrival
can be left out, so that a cleat recording yields its own no-cleat profile.

Result: :class:`RollingProfile`, written as ``*.profile.csv`` (docs/formats.md §3)
with :func:`ringfit.io.profiles.write_profile` after :meth:`RollingProfile.to_profile`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ringfit.errors import InputError
from ringfit.io.continuous import DEFAULT_CHUNK, ContinuousRecord
from ringfit.io.profiles import band_limited_resample, grid_angles_deg
from ringfit.io.record_types import CONDITION_KEYS, Axis

#: Default number of angle points of a profile (0.18° spacing).
DEFAULT_POINTS = 2048


@dataclass
class RollingProfile:
    """A per-revolution profile averaged over revolutions.

    **Fields:**

    - ``angle_deg``: (M,) bin centres φ_j = −180 + 360 j/M [deg].
    - ``axes``: axis names of the rows below.
    - ``mean``: (axes, M) average reading [m/s²].
    - ``spread``: (axes, M) revolution-to-revolution standard deviation [m/s²] (noise estimate).
    - ``revolutions``: (M,) revolutions that contributed to each bin.
    - ``rotation_hz``: wheel rotation rate from the encoder [Hz].
    - ``fs_hz``: sample rate [Hz]; ``condition``: the record's condition keys.
    """

    angle_deg: np.ndarray
    axes: tuple
    mean: np.ndarray
    spread: np.ndarray
    revolutions: np.ndarray
    rotation_hz: float
    fs_hz: float
    condition: dict = field(default_factory=dict)

    @property
    def full_revolutions(self) -> int:
        """Revolutions that reached every bin (the sidecar's ``revolutions``)."""
        return int(self.revolutions.min())

    def standard_error(self) -> np.ndarray:
        """(axes, M) standard error of the mean, spread/√revolutions [m/s²]."""
        return self.spread / np.sqrt(np.maximum(self.revolutions, 1))

    def channel(self, axis: str) -> np.ndarray:
        """(M,) mean reading of one axis [m/s²]."""
        if axis not in self.axes:
            raise InputError(f"profile has no '{axis}' axis (have: {', '.join(self.axes)})")
        return self.mean[self.axes.index(axis)]

    def interpolator(self, axis: str, refine: int = 16384):
        """A function φ [deg] → reading [m/s²] (band-limited refinement to ``refine`` points, then linear)."""
        return periodic_interpolator(self.channel(axis), refine)

    def to_profile(self):
        """The docs/formats.md §3 :class:`~ringfit.io.profiles.Profile` (radial and tangential; the spread as extra columns).

        A missing axis is written as zeros and said so in the sidecar
        (``missing_axes``); ``revolutions`` is the count that reached every bin.
        """
        from ringfit.io.profiles import Profile

        cols, missing, extra = {}, [], {}
        for axis in ("radial", "tangential"):
            if axis in self.axes:
                cols[axis] = self.channel(axis)
                extra[f"acc_{axis}_spread_ms2"] = np.array([repr(float(x)) for x in self.spread[self.axes.index(axis)]],
                                                           dtype=object)
            else:
                cols[axis] = np.zeros_like(self.angle_deg)
                missing.append(axis)
        # every stated condition the recording carries (docs/formats.md §3): the state keys too (torque_nm,
        # tread_depth_mm), which ``identify`` needs; the rotation is the one measured here, not the stated one
        cond = {k: float(self.condition[k]) for k in CONDITION_KEYS
                if k != "rotation_hz" and self.condition.get(k) is not None}
        cond.update(revolutions=self.full_revolutions, sample_rate_hz=float(self.fs_hz),
                    rotation_hz=float(self.rotation_hz))
        if missing:
            cond["missing_axes"] = missing
        return Profile(self.angle_deg, cols["radial"], cols["tangential"], condition=cond, extra=extra)


def periodic_interpolator(values: np.ndarray, refine: int = 16384):
    """φ [deg] → value for a periodic grid signal on φ_j = −180 + 360 j/M.

    The signal is first refined to ``refine`` points by zero-padding its
    spectrum (band-limited, Nyquist dropped), then interpolated linearly —
    accurate for the sharp patch-edge features without per-sample FFTs.
    """
    values = np.asarray(values, dtype=np.float64)
    refine = max(int(refine), values.size)
    table = band_limited_resample(values, refine)
    # one period closed at +180 (np.interp's `period=` would re-sort the table at every call)
    table = np.append(table, table[0])
    grid = np.append(grid_angles_deg(refine), 180.0)

    def interp(phi_deg):
        return np.interp(np.mod(np.add(phi_deg, 180.0), 360.0) - 180.0, grid, table)

    return interp


def rolling_profile(
    record: ContinuousRecord,
    *,
    points: int = DEFAULT_POINTS,
    axes=None,
    arrivals_samples=None,
    quiet_after_s: float | None = None,
    chunk: int = DEFAULT_CHUNK,
    progress: bool = False,
) -> RollingProfile:
    """Average the readings of a continuous record by sensor angle over revolutions.

    **Arguments:**

    - ``record``: a :class:`~ringfit.io.continuous.ContinuousRecord` with an encoder.
    - ``points``: M angle bins (centres φ_j = −180 + 360 j/M).
    - ``axes``: axis names to profile (default all of the record's).
    - ``arrivals_samples``: (K,) cleat arrivals as (fractional) sample indices;
      with ``quiet_after_s`` the samples with 0 ≤ τ < quiet_after_s after an
      arrival are left out (and everything before the first arrival is kept).
    - ``chunk``: samples per chunk; ``progress``: tqdm bar on stderr.

    **Returns:** :class:`RollingProfile`.

    **Raises:** :class:`InputError` without an encoder, with fewer than 2
    revolutions, or when a bin gets no samples (too few revolutions for ``points``).
    """
    if not record.has_encoder:
        raise InputError("no encoder channel ('encoder_angle_deg' or 'encoder_pulses'); "
                         "a profile needs the sensor angle", source=record.source)
    points = int(points)
    if points < 16:
        raise InputError(f"points = {points}; a profile needs at least 16 angles")
    axes = tuple(record.axes if axes is None else axes)
    rows = [record.axis_index(a) for a in axes]
    exclude = arrivals_samples is not None and quiet_after_s
    if exclude:
        arrivals = np.asarray(arrivals_samples, dtype=np.float64)
        quiet = float(quiet_after_s) * record.fs_hz

    na = len(axes)
    s1 = np.zeros((na, points))  # Σ over revolutions of x̄_rj
    s2 = np.zeros((na, points))  # Σ of x̄_rj²
    nrev = np.zeros(points, dtype=np.int64)
    carry = None  # (rev, sums (na, M), counts (M,)) of the revolution still open at the chunk end
    first_angle = last_angle = None

    from tqdm import tqdm

    from ringfit.targets.faults import EncoderTiming

    timing = EncoderTiming()
    bar = tqdm(total=record.samples, unit="sample", unit_scale=True, disable=not progress, desc="profile")
    for ch in record.chunks(chunk):
        phi = ch.angle_deg
        if "encoder_angle_deg" in record._channels:  # an incremental encoder's angle is interpolated: no steps
            timing.add(phi, ch.acc)
        if first_angle is None:
            first_angle = phi[0]
        last_angle = phi[-1]
        x = ch.acc[rows]
        keep = None
        if exclude:
            idx = np.arange(ch.start, ch.start + len(ch), dtype=np.float64)
            k = np.searchsorted(arrivals, idx, side="right") - 1
            tau = np.where(k >= 0, idx - arrivals[np.maximum(k, 0)], np.inf)
            keep = tau >= quiet
        # revolution number: count of passes through φ ≡ −180 (bin edges are centred on φ_j)
        shifted = phi + 180.0 + 180.0 / points
        rev = np.floor(shifted / 360.0).astype(np.int64)
        b = np.floor((shifted - 360.0 * rev) * points / 360.0).astype(np.int64) % points
        if keep is not None:
            rev, b, x = rev[keep], b[keep], x[:, keep]
        if rev.size == 0:
            bar.update(len(ch))
            continue
        r0 = int(rev[0]) if carry is None else min(int(rev[0]), carry[0])
        nr = int(rev[-1]) - r0 + 1
        flat = (rev - r0) * points + b
        cnt = np.bincount(flat, minlength=nr * points).reshape(nr, points)
        sums = np.stack([np.bincount(flat, weights=x[i], minlength=nr * points) for i in range(na)])
        sums = sums.reshape(na, nr, points)
        if carry is not None:
            j = carry[0] - r0
            sums[:, j] += carry[1]
            cnt[j] += carry[2]
        # every revolution but the last is complete
        _accumulate(sums[:, :-1], cnt[:-1], s1, s2, nrev)
        carry = (r0 + nr - 1, sums[:, -1].copy(), cnt[-1].copy())
        bar.update(len(ch))
    bar.close()
    if carry is not None:
        _accumulate(carry[1][:, None], carry[2][None], s1, s2, nrev)

    total_rev = (last_angle - first_angle) / 360.0 if first_angle is not None else 0.0
    if total_rev < 2:
        raise InputError(f"the recording covers {total_rev:.2f} revolutions; a profile needs at least 2 "
                         "(a frozen or disconnected encoder?)",
                         source=record.source)
    if (nrev == 0).any():
        j = int(np.argmax(nrev == 0))
        raise InputError(
            f"angle bin {grid_angles_deg(points)[j]:.3f} deg got no samples; use fewer points than {points} "
            "or a longer recording", source=record.source)
    mean = s1 / nrev
    with np.errstate(invalid="ignore", divide="ignore"):
        var = (s2 - nrev * mean**2) / (nrev - 1)
    spread = np.sqrt(np.clip(np.where(nrev > 1, var, np.nan), 0.0, None))
    import warnings

    said = timing.note()
    samples = timing.covered if said else record.samples
    rotation_hz = total_rev / ((samples - 1) / record.fs_hz)
    from ringfit.targets.faults import sample_rate_note

    if said:
        warnings.warn(f"{record.source}: {said}", RuntimeWarning, stacklevel=2)
    note = sample_rate_note(rotation_hz, record.fs_hz, dict(record.condition))
    if note:
        warnings.warn(f"{record.source}: {note}", RuntimeWarning, stacklevel=2)
    return RollingProfile(
        angle_deg=grid_angles_deg(points),
        axes=axes,
        mean=mean,
        spread=spread,
        revolutions=nrev,
        rotation_hz=float(rotation_hz),
        fs_hz=float(record.fs_hz),
        condition=dict(record.condition),
    )


def _accumulate(sums, counts, s1, s2, nrev):
    """Add the bin means of complete revolutions (sums (na, r, M), counts (r, M)) to the accumulators."""
    have = counts > 0
    if not have.any():
        return
    means = np.where(have, sums / np.maximum(counts, 1), 0.0)
    s1 += means.sum(axis=1)
    s2 += (means**2).sum(axis=1)
    nrev += have.sum(axis=0)


# ----------------------------------------------------------------------------- single revolutions

#: Samples of the neighbouring revolutions on either side kept in a revolution's angle fit and interpolation.
REVOLUTION_MARGIN = 8


@dataclass
class RevolutionGrid:
    """Whole revolutions of a continuous recording, each resampled onto the angle grid (see :func:`revolution_grids`).

    **Fields** (r revolutions): ``revolution`` (r,) numbers (revolution n covers the unwrapped sensor
    angle [360 n − 180, 360 n + 180) deg); ``t_s`` (r,) time of its middle [s] from the first sample;
    ``rotation_hz`` (r,) its rotation rate [Hz] (angle fit); ``values`` (axes, r, M) the readings at
    φ_j = −180 + 360 j/M [m/s²]; ``samples`` (r,) samples it holds; ``fractions`` ``(3, B)`` over the block's
    grid points, per bin of the interpolation's fraction f (:data:`FRACTION_BINS`): their count, the sum of
    the sample spacings [deg] they fell between and the sum of their fractions (what
    :func:`interpolation_response` reads).
    """

    revolution: np.ndarray
    t_s: np.ndarray
    rotation_hz: np.ndarray
    values: np.ndarray
    samples: np.ndarray
    fractions: np.ndarray

    def __len__(self) -> int:
        return self.revolution.size


#: Bins of the linear interpolation's fraction f ∈ [0, 1) that :func:`interpolation_response` averages over.
FRACTION_BINS = 128


def interpolation_response(fractions: np.ndarray, k: np.ndarray) -> np.ndarray:
    """The complex gain ``(K,)`` on the revolution harmonics ``k`` of linear interpolation at the grid points that
    ``fractions`` (``RevolutionGrid.fractions`` summed over blocks: count, spacing sum and fraction sum per bin)
    describes (docs/physics.md §10 *the acquisition's gain*). A grid point at fraction f of the way between
    samples Δ apart reads harmonic k (θ = kΔ) with H = (1 − f)e^{−iθf} + f e^{iθ(1−f)}; returned is H averaged
    over the grid points. Sampling locked to the angle (f = 0 everywhere) gives 1; fractions spread evenly over
    [0, 1) give sinc²(kΔ/2π), the triangle kernel's transform; a fixed f ≠ ½ adds a phase of O(θ³)."""
    count, spacing, fsum = np.asarray(fractions, dtype=np.float64)
    have = count > 0
    n = count[have]
    f = fsum[have] / n  # each bin at its points' mean fraction: exact where they share one (sampling locked)
    delta = np.radians(spacing[have] / n)
    theta = np.asarray(k, dtype=np.float64)[:, None] * delta[None, :]
    h = (1 - f) * np.exp(-1j * theta * f) + f * np.exp(1j * theta * (1 - f))
    return (h * n).sum(axis=1) / n.sum()  # not BLAS: its threads would spin on this small product


def revolution_grids(record: ContinuousRecord, *, points: int, axes=("radial",), chunk: int = DEFAULT_CHUNK,
                     passages=None, progress: bool = False):
    """Walk a recording and yield each whole revolution's readings on the angle grid (bounded memory).

    Per revolution, the decoded encoder angle is replaced by a quadratic fit of angle against time
    over the revolution's samples (removing the encoder's quantisation and pulse interpolation
    while following a steady acceleration), and the readings are interpolated linearly at
    φ_j = −180 + 360 j/M. Unlike the bins of :func:`rolling_profile`, whose average is not the
    bin's centre when a bin holds a few samples, the grid values sit at known angles; linear
    interpolation between samples Δ apart attenuates revolution harmonic k by about
    sinc²(kΔ/2π) (0.998 at k = 40 with 1800 samples per revolution).

    **Arguments:** ``record`` (with an encoder), ``points`` M, ``axes``, ``chunk``, ``progress``;
    ``passages``: without an encoder, the sample positions of the sensor's passages through the
    contact patch (:func:`patch_passages`): the angle is then 360° × the passage count, linear in
    time between passages (φ = 0 at each passage, so the angle offset is the dip's lag behind the
    patch centre), and samples before the first or after the last passage are left out.
    **Yields:** :class:`RevolutionGrid` blocks (the first and last, partial revolutions are left out).

    **Raises:** :class:`InputError` without an encoder and passages, or when ``points`` < 16.
    """
    if passages is not None:
        passages = np.asarray(passages, dtype=np.float64)
        if passages.size < 3 or np.any(np.diff(passages) <= 0):
            raise InputError("fewer than 3 patch passages, or not increasing", source=record.source)
    elif not record.has_encoder:
        raise InputError("no encoder channel ('encoder_angle_deg' or 'encoder_pulses'); "
                         "per-revolution readings need the sensor angle", source=record.source)
    points = int(points)
    if points < 16:
        raise InputError(f"points = {points}; a revolution needs at least 16 angles")
    axes = tuple(axes)
    rows = [record.axis_index(a) for a in axes]
    grid = 360.0 * np.arange(points) / points  # from the revolution's start
    fs = float(record.fs_hz)
    tail = None  # (idx, phi, x) of the samples not yet used
    from tqdm import tqdm

    bar = tqdm(total=record.samples, unit="sample", unit_scale=True, disable=not progress, desc="revolutions")
    for ch in record.chunks(chunk):
        idx = np.arange(ch.start, ch.stop, dtype=np.float64)
        x = ch.acc[rows]
        if passages is None:
            phi = ch.angle_deg
        else:
            inside = (idx >= passages[0]) & (idx <= passages[-1])
            idx, x = idx[inside], x[:, inside]
            phi = 360.0 * np.interp(idx, passages, np.arange(passages.size, dtype=np.float64))
        if tail is not None:
            idx, phi, x = np.concatenate([tail[0], idx]), np.concatenate([tail[1], phi]), np.concatenate([tail[2], x], 1)
        bar.update(len(ch))
        if idx.size == 0:
            continue
        rev = np.floor((phi + 180.0) / 360.0).astype(np.int64)
        # whole revolutions with REVOLUTION_MARGIN samples of their neighbours on both sides in the buffer
        numbers = np.arange(rev[0] + 1, rev[-1])
        lo = np.searchsorted(rev, numbers, side="left")
        hi = np.searchsorted(rev, numbers, side="right")
        ready = (lo >= REVOLUTION_MARGIN) & (hi + REVOLUTION_MARGIN <= rev.size) & (hi - lo >= 8)
        numbers, lo, hi = numbers[ready], lo[ready], hi[ready]
        if numbers.size:
            out = np.empty((len(axes), numbers.size, points))
            t_mid = np.empty(numbers.size)
            rate = np.empty(numbers.size)
            fractions = np.zeros((3, FRACTION_BINS))
            for j, (n, a, b) in enumerate(zip(numbers, lo, hi)):
                s = slice(a - REVOLUTION_MARGIN, b + REVOLUTION_MARGIN)
                t = idx[s] / fs
                tc = 0.5 * (t[REVOLUTION_MARGIN] + t[-REVOLUTION_MARGIN - 1])
                c = np.polyfit(t - tc, phi[s], 2)
                smooth = np.polyval(c, t - tc)
                target = 360.0 * n - 180.0 + grid
                for i in range(len(axes)):
                    out[i, j] = np.interp(target, smooth, x[i, s])
                # where the grid points fell between samples: the interpolation's gain (interpolation_response);
                # searched again beside np.interp, which is C and keeps its own search (measured: faster than one
                # search and a NumPy interpolation of both axes)
                at = np.minimum(np.maximum(np.searchsorted(smooth, target, side="right"), 1), smooth.size - 1)
                gap = smooth[at] - smooth[at - 1]
                frac = np.minimum(np.maximum((target - smooth[at - 1]) / np.where(gap > 0, gap, 1.0), 0.0),
                                  1.0 - 1e-12)
                b = (frac * FRACTION_BINS).astype(np.int64)
                fractions[0] += np.bincount(b, minlength=FRACTION_BINS)
                fractions[1] += np.bincount(b, weights=gap, minlength=FRACTION_BINS)
                fractions[2] += np.bincount(b, weights=frac, minlength=FRACTION_BINS)
                t_mid[j] = tc
                rate[j] = c[1] / 360.0
            yield RevolutionGrid(numbers, t_mid, rate, out, hi - lo, fractions)
            cut = max(int(hi[-1]) - REVOLUTION_MARGIN, 0)
        else:  # keep everything from the first candidate revolution on
            cut = max(int(np.searchsorted(rev, rev[0] + 1, side="left")) - REVOLUTION_MARGIN, 0)
        tail = (idx[cut:], phi[cut:], x[:, cut:])
    bar.close()


#: Passages are searched in the reading smoothed over this fraction of a revolution.
PASSAGE_SMOOTHING = 1.0 / 200.0
#: Samples at the start of a recording from which the threshold and the revolution period are learnt.
PASSAGE_LEARN = 1 << 20


def patch_passages(record: ContinuousRecord, *, axis: Axis = "radial", chunk: int = DEFAULT_CHUNK,
                   progress: bool = False) -> np.ndarray:
    """Sample positions of the sensor's passages through the contact patch, from the reading alone.

    Inside the patch the belt is flat and the radial reading (toward the centre +) drops by about
    Ω²R below its level elsewhere (docs/physics.md §5): far more than gravity (1 g) at any speed
    above ~10 km/h. The reading, smoothed over :data:`PASSAGE_SMOOTHING` of a revolution, is
    thresholded halfway between its median and its deep-dip level (the 0.5th percentile of the first
    :data:`PASSAGE_LEARN` samples, which also give the revolution period by autocorrelation); each run below the threshold is one passage, placed at the centroid of its depth below
    the threshold. Runs shorter than 1/400 of a revolution or closer than half a revolution to the
    previous passage are dropped.

    **Arguments:** the recording, the axis (``radial``), ``chunk``, ``progress``.
    **Returns:** ``(P,)`` fractional sample indices, increasing.
    **Raises:** :class:`InputError` when the reading shows no regular dips.
    """
    row = record.axis_index(axis)
    first = record.read(f"acc:{axis}", 0, min(record.samples, PASSAGE_LEARN))
    base, deep = float(np.median(first)), float(np.percentile(first, 0.5))
    threshold = 0.5 * (base + deep)
    # the revolution period: the first autocorrelation peak (above 80 % of the largest) after it turns negative
    n = first.size
    y = first - base
    ac = np.fft.irfft(np.abs(np.fft.rfft(y, 2 * n)) ** 2)[: n // 2] / (n - np.arange(n // 2))
    negative = np.flatnonzero(ac < 0)
    period = math.nan
    if negative.size and deep < base and ac[negative[0]:].max() > 0.3 * ac[0]:  # regular dips
        lag = ac[negative[0]:]
        peaks = np.flatnonzero((lag[1:-1] > lag[:-2]) & (lag[1:-1] >= lag[2:])) + 1
        peaks = peaks[lag[peaks] > 0.8 * lag.max()] if peaks.size else peaks
        if peaks.size:
            period = float(negative[0] + peaks[0])
    if not period > 8 or period * 3 > n:
        raise InputError(f"no regular dips in the '{axis}' reading of the first {n} samples: the patch "
                         "passages cannot be found (and there is no encoder)", source=record.source)
    width = max(1, int(round(PASSAGE_SMOOTHING * period)))
    kernel = np.ones(width) / width
    from tqdm import tqdm

    bar = tqdm(total=record.samples, unit="sample", unit_scale=True, disable=not progress, desc="patch passages")
    out = []
    carry = np.zeros(0)  # the last width − 1 samples of the previous chunk (for the moving average)
    run = None  # (Σ weight·index, Σ weight, length) of a run still open at the chunk end
    for ch in record.chunks(chunk):
        bar.update(len(ch))
        x = np.concatenate([carry, ch.acc[row]])
        smooth = np.convolve(x, kernel, mode="valid")  # smooth[j] averages x[j : j + width]
        pos = ch.start - carry.size + np.arange(smooth.size) + 0.5 * (width - 1)
        carry = x[-(width - 1):] if width > 1 else np.zeros(0)
        depth = np.where(smooth < threshold, threshold - smooth, 0.0)
        inside = depth > 0
        edges = np.flatnonzero(np.diff(np.concatenate([[False], inside, [False]]).astype(np.int8)))
        runs = list(zip(edges[::2], edges[1::2]))
        if run is not None and (not runs or runs[0][0] > 0):  # the open run ended at the chunk boundary
            out.append(run)
            run = None
        for a, b in runs:
            stats = ((depth[a:b] * pos[a:b]).sum(), depth[a:b].sum(), b - a)
            if run is not None:  # continues the run left open by the previous chunk
                stats = tuple(u + v for u, v in zip(stats, run))
                run = None
            if b == inside.size:
                run = stats
            else:
                out.append(stats)
    if run is not None:
        out.append(run)
    bar.close()
    times = np.array([s / w for s, w, n in out if n >= period / 400.0 and w > 0])
    keep = [0]
    for i in range(1, times.size):
        if times[i] - times[keep[-1]] > 0.5 * period:
            keep.append(i)
    times = times[keep] if times.size else times
    if times.size < 3:
        raise InputError(f"only {times.size} patch passages found in the '{axis}' reading (and no encoder)",
                         source=record.source)
    return times


__all__ = ["RollingProfile", "rolling_profile", "periodic_interpolator", "DEFAULT_POINTS",
           "revolution_grids", "RevolutionGrid", "patch_passages", "interpolation_response", "FRACTION_BINS"]
