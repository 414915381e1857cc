"""Degraded records: offsets removed, dead and junk channels found, noise-dominated tests called out.

Real impact records are not clean: an IEPE channel carries a DC offset (or
gravity), an axis is unplugged (flat), one channel picks up hum or noise
instead of the tyre, or the whole test drowns in noise. Left in, each turns
into a silently wrong mode table (an offset of 100× the signal turns the
shapes of half the modes into n = 0). This module handles each and says so:

- :func:`remove_drift` — a DC drift (a ramp, a slow wander) taken for a polynomial trend of each channel and
  subtracted where some channel drifts (left in, it swamps the late decay and the test reads as noise);
- :func:`remove_offsets` — subtract each channel's offset, the mean of its
  samples before the impact when there are enough of them, else its mean
  over the record;
- :func:`screen_channels` — per channel of the aligned decays: **flat**
  (standard deviation below 1e-9 of the median: dead), **junk** (no free
  decay — the first quarter of the decay holds less than ``JUNK_DECAY`` × the
  rms of the last quarter — while the typical channel decays by more than
  ``GOOD_DECAY`` ×), **out of scale** (rms above ``SCALE_LIMIT`` × the median:
  a wrong gain). Those are left out;
- a **noise-dominated** test: the typical channel does not decay by
  ``GOOD_DECAY`` × (a test with noise ten times the signal looks like this) —
  nothing is dropped, but the result is marked as not credible.

Every finding is a one-line note; :mod:`ringfit.targets.identify` and
:mod:`ringfit.targets.frf` put the notes in the mode table's sidecar
(``preprocessing``, ``credible``) and raise them as warnings.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ringfit.errors import InputError

#: A channel whose early decay rms is below this multiple of its late rms does not decay.
JUNK_DECAY = 1.5
#: The median channel of a usable test decays by more than this factor.
GOOD_DECAY = 3.0
#: rms above this multiple of the median rms is out of scale (weak channels are kept: a sensor near a node).
SCALE_LIMIT = 30.0
#: Fewest pre-impact samples used to estimate an offset.
MIN_PRE_SAMPLES = 32
#: An offset is worth a note when it exceeds this fraction of the channel's standard deviation.
NOTE_OFFSET = 0.5
#: Degree of the polynomial trend (drift) fitted to each channel.
DRIFT_DEGREE = 2
#: A channel drifts when its fitted trend moves by more than this share of the channel's rms about the trend.
DRIFT_REL = 0.25


@dataclass
class ChannelScreen:
    """What :func:`screen_channels` found.

    - ``keep``: bool ``(channels,)``, channels used.
    - ``reason``: ``(channels,)`` str, ``""`` for kept ones, else ``flat``, ``junk`` or ``scale``.
    - ``decay_ratio``: ``(channels,)`` early/late rms of each channel's decay.
    - ``credible``: False when the typical channel shows no free decay above noise.
    - ``notes``: one-line findings, for the user and the sidecar.
    """

    keep: np.ndarray
    reason: np.ndarray
    decay_ratio: np.ndarray
    credible: bool = True
    notes: list[str] = field(default_factory=list)


def remove_offsets(acc: np.ndarray, impact_index: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Subtract each channel's offset.

    **Arguments:** ``acc`` (records, axes, samples) [m/s²]; ``impact_index``
    (records,) sample of the impact in each record, or None.

    **Returns:** ``(acc_without_offsets, offsets)`` with offsets (records, axes) [m/s²]:
    the mean before the impact where at least :data:`MIN_PRE_SAMPLES` precede
    it, else the mean over the whole record.
    """
    acc = np.asarray(acc, dtype=np.float64)
    offsets = acc.mean(axis=-1)
    if impact_index is not None:
        for r, k in enumerate(np.asarray(impact_index, dtype=np.int64)):
            if k >= MIN_PRE_SAMPLES:
                offsets[r] = acc[r, :, :k].mean(axis=-1)
    return acc - offsets[..., None], offsets


def drift_trend(acc: np.ndarray, degree: int = DRIFT_DEGREE) -> np.ndarray:
    """The least-squares polynomial trend of each channel, without its mean: same shape as ``acc``
    (Legendre basis over the record; a decay's oscillation barely projects on it)."""
    s = acc.shape[-1]
    t = np.linspace(-1.0, 1.0, s)
    basis = np.polynomial.legendre.legvander(t, degree)  # (samples, degree + 1)
    coef, *_ = np.linalg.lstsq(basis, acc.reshape(-1, s).T, rcond=None)
    return (basis[:, 1:] @ coef[1:]).T.reshape(acc.shape)  # the constant is the offset's (remove_offsets)


def remove_drift(acc: np.ndarray) -> tuple[np.ndarray, str | None]:
    """Each channel's polynomial trend (:func:`drift_trend`) removed when some channel drifts (the trend moves by
    more than :data:`DRIFT_REL` of its rms about the trend); then every channel is detrended alike.

    **Returns:** ``(acc, note)``, ``acc`` unchanged and ``note`` None when nothing drifts.
    """
    acc = np.asarray(acc, dtype=np.float64)
    if acc.shape[-1] < 4 * (DRIFT_DEGREE + 1):
        return acc, None
    trend = drift_trend(acc)
    rest = acc - trend
    spread = np.ptp(trend, axis=-1)
    rms = np.std(rest, axis=-1)
    drifts = spread > DRIFT_REL * np.maximum(rms, np.finfo(float).tiny)
    if not drifts.any():
        return acc, None
    i = np.unravel_index(np.argmax(np.where(drifts, spread / np.maximum(rms, np.finfo(float).tiny), 0)), drifts.shape)
    worst = float(spread[i] / max(rms[i], np.finfo(float).tiny))
    return rest, (f"drift in {int(drifts.sum())} of {drifts.size} channels (a trend moving up to "
                  f"{float(spread.max()):.3g} m/s² over the record, {worst:.3g}× the channel's rms about it): "
                  f"removed (a polynomial trend of degree {DRIFT_DEGREE} fitted to each channel and subtracted)")


def clean_records(records, threshold: float = 0.1):
    """Drift removed (:func:`remove_drift`: a polynomial trend, where some channel
    drifts), offsets removed (:func:`remove_offsets`, pre-impact mean where the force shows the impact) and
    axes that are flat on every record (a dead axis) left out.

    **Returns:** ``(records, notes)`` — new :class:`~ringfit.io.records.Records` and one-line notes.
    """
    from dataclasses import replace

    from ringfit.targets.preprocessing import impact_indices

    notes = []
    idx = impact_indices(records.force, threshold) if records.force is not None else None
    acc, drift = remove_drift(records.acc)
    if drift:
        notes.append(drift)
    acc, offsets = remove_offsets(acc, idx)
    note = offset_note(offsets, acc)
    if note:
        notes.append(note)
    dead = [a for j, a in enumerate(records.axes) if not np.any(acc[:, j].std(axis=-1) > 0)]
    if len(dead) == len(records.axes):
        raise InputError("every acceleration channel is flat (all zero or constant); nothing to identify",
                         source=records.source)
    if dead:
        keep = [j for j, a in enumerate(records.axes) if a not in dead]
        notes.append(f"axis {', '.join(repr(a) for a in dead)} flat on every record (a dead axis): left out")
        return replace(records, acc=acc[:, keep], axes=tuple(records.axes[j] for j in keep)), notes
    return replace(records, acc=acc), notes


def offset_note(offsets: np.ndarray, acc: np.ndarray) -> str | None:
    """A one-line note when some offset exceeds :data:`NOTE_OFFSET` of its channel's spread."""
    spread = np.std(acc, axis=-1)
    big = np.abs(offsets) > NOTE_OFFSET * np.maximum(spread, np.finfo(float).tiny)
    if not big.any():
        return None
    return (f"offset removed from {int(big.sum())} of {big.size} channels (up to {np.max(np.abs(offsets)):.3g} m/s², "
            f"{np.max(np.abs(offsets) / np.maximum(spread, np.finfo(float).tiny)):.3g}× the channel's spread)")


def screen_channels(y: np.ndarray, labels: list[str] | None = None) -> ChannelScreen:
    """Find flat, junk and out-of-scale channels among free decays (see the module docstring).

    **Arguments:** ``y`` (channels, samples) aligned decays with offsets
    removed; ``labels`` a name per channel for the notes (e.g. ``"45° radial"``).

    **Raises** :class:`InputError` when every channel is flat (e.g. all-zero records).
    """
    y = np.asarray(y, dtype=np.float64)
    c, s = y.shape
    labels = labels or [f"channel {i}" for i in range(c)]
    std = y.std(axis=1)
    reason = np.full(c, "", dtype=object)
    live = std > 0
    if not live.any():
        raise InputError("every acceleration channel is flat (all zero or constant); nothing to identify")
    typical = float(np.median(std[live]))
    reason[std <= 1e-9 * typical] = "flat"
    q = max(1, s // 4)
    early = np.sqrt(np.mean(y[:, :q] ** 2, axis=1))
    late = np.sqrt(np.mean(y[:, -q:] ** 2, axis=1))
    ratio = early / np.maximum(late, np.finfo(float).tiny)
    ok = reason == ""
    median_ratio = float(np.median(ratio[ok])) if ok.any() else 0.0
    credible = median_ratio >= GOOD_DECAY
    if credible:
        reason[ok & (ratio < JUNK_DECAY)] = "junk"
    ok = reason == ""
    if ok.sum() >= 3:
        ref = float(np.median(std[ok]))
        reason[ok & (std > SCALE_LIMIT * ref)] = "scale"  # weak channels are fine: a sensor near a node
    keep = reason == ""
    notes = []
    words = {"flat": "flat (dead)", "junk": "without a free decay (junk)",
             "scale": f"out of scale (rms above {SCALE_LIMIT:g}× the median)"}
    for why in ("flat", "junk", "scale"):
        idx = np.flatnonzero(reason == why)
        if idx.size:
            shown = ", ".join(labels[i] for i in idx[:6]) + (f" and {idx.size - 6} more" if idx.size > 6 else "")
            notes.append(f"{idx.size} channel(s) {words[why]} left out: {shown}")
    if not keep.any():
        raise InputError("no usable acceleration channel: " + "; ".join(notes))
    if not credible:
        notes.append(f"the decays do not rise above the noise (first quarter only {median_ratio:.2g}× the rms of "
                     f"the last, expected > {GOOD_DECAY:g}×): noise dominates these records and the modes found "
                     "are not credible")
    return ChannelScreen(keep, reason, ratio, credible, notes)


def channel_labels(angle_deg: np.ndarray, axes) -> list[str]:
    """``"<angle>° <axis>"`` for each channel of (angles, axes) in channel order."""
    return [f"{a:g}° {ax}" for a in np.asarray(angle_deg) for ax in axes]


def psd_singular_values(y: np.ndarray, fs_hz: float, *, segment: int | None = None, k: int = 3,
                        nfft: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """Singular values of the channels' cross-power spectral matrix (Welch, Hann, 75 % overlap): a CMIF-like
    background for the stabilization diagram, one curve per independent motion at each frequency.

    **Arguments:** ``y`` (channels, samples) [m/s²]; ``segment`` samples per Welch segment (default half
    the record); ``k`` how many singular values to keep; ``nfft`` FFT length (segments zero-padded).

    **Returns:** ``(freq_hz (F,), sv (F, k))`` in (m/s²)²/Hz, largest first.
    """
    y = np.asarray(y, dtype=np.float64)
    c, s = y.shape
    nper = int(segment or max(16, s // 2))
    nper = min(nper, s)
    step = max(1, nper // 4)
    win = np.hanning(nper)
    n = max(nfft, nper)
    starts = list(range(0, s - nper + 1, step)) or [0]
    spec = np.stack([np.fft.rfft(y[:, i:i + nper] * win, n, axis=1) for i in starts], axis=-1)  # (c, F, segs)
    sv = np.linalg.svd(np.moveaxis(spec, 1, 0), compute_uv=False) ** 2  # (F, min(c, segs))
    sv /= len(starts) * fs_hz * np.sum(win**2)
    out = np.zeros((sv.shape[0], k))
    out[:, : min(k, sv.shape[1])] = sv[:, :k]
    return np.fft.rfftfreq(n, 1.0 / fs_hz), out
