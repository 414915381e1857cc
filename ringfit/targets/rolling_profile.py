"""Rolling profiles from a continuous recording: per-revolution readings by sensor angle, averaged.

On a smooth drum or road every revolution reads the same (the source's figure
22), so the profile is the average over revolutions of the readings binned by
sensor angle φ, and the revolution-to-revolution spread is the noise estimate
that the rolling fit and the gap diagnosis weight by.

The recording is walked in chunks (bounded memory). For every revolution r
and angle bin j (``points`` bins centred on φ_j = −180 + 360 j/M, DATA.md §3)
the samples are averaged into x̄_rj; the profile is the mean of x̄_rj over
the revolutions that have samples in bin j, the spread their standard
deviation (ddof = 1). Samples within ``quiet_after_s`` of a cleat arrival
can be left out, so that a cleat recording yields its own no-cleat profile.

Result: :class:`RollingProfile`, written as ``*.profile.csv`` (DATA.md §3)
with :func:`ringfit.io.profiles.write_profile` after :meth:`RollingProfile.to_profile`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ringfit.errors import InputError
from ringfit.io.continuous import DEFAULT_CHUNK, ContinuousRecord
from ringfit.io.profiles import band_limited_resample, grid_angles_deg

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
        """The DATA.md §3 :class:`~ringfit.io.profiles.Profile` (radial and tangential; the spread as extra columns).

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
        cond = {k: float(self.condition[k]) for k in ("speed_kmh", "load_n", "pressure_bar", "drum_diameter_m")
                if self.condition.get(k) is not None}
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

    bar = tqdm(total=record.samples, unit="sample", unit_scale=True, disable=not progress, desc="profile")
    for ch in record.chunks(chunk):
        phi = ch.angle_deg
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
    rotation_hz = total_rev / ((record.samples - 1) / record.fs_hz)
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


def profile_rms_error(profile: RollingProfile, truth, axis: str = "radial") -> float:
    """RMS difference [m/s²] between a profile and a truth function φ [deg] → reading (for tests and benchmarks)."""
    return float(np.sqrt(np.mean((profile.channel(axis) - truth(profile.angle_deg)) ** 2)))


__all__ = ["RollingProfile", "rolling_profile", "periodic_interpolator", "profile_rms_error", "DEFAULT_POINTS"]
