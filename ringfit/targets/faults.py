"""Rig faults in impact records, found on each channel of each record before anything is averaged
(docs/physics.md §9 *rig faults*).

A fault left in makes modes that are not there or hides those that are. Each check works on one channel (record,
axis) with its offset removed and gives a one-line note for the sidecar's ``preprocessing`` list and a warning:
**dead** (:data:`DEAD_REL`), **clipped** (:data:`CLIP_RUN`, :func:`clip_runs`), **spikes** (a robust z of the
derivative scaled by the second difference, :func:`spike_segments`), **mains hum** (a steady line at h × 50 or
h × 60 Hz in the record's late half, notched: :func:`hum_lines`), **sign-flipped** against the other repeats of
an angle, and against the ring's mode shapes where a force channel is recorded (:func:`shape_scores`). Timing
faults come first (:func:`repair_timing`; :class:`EncoderTiming` in continuous recordings). Hum is notched; a
faulty channel is left out of its record where a clean repeat carries its angle, else bridged (spikes) or turned
round (a flip against the shapes). Every threshold, and why it is where it is: docs/physics.md §9.

Example (what ``ringfit ssi`` runs before the SSI)::

    from ringfit.io.records import read_records
    from ringfit.targets.faults import repair_records
    from ringfit.targets.quality import clean_records

    records, use, notes, hum_hz = repair_records(clean_records(read_records("ex/impact.records.npz"))[0])
    print(notes, use.sum(), "channels used")
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ringfit.io.conditions import RATE_TOL, ROLLING_RADIUS_M
from ringfit.targets.preprocessing import SKIP_AFTER_IMPACT_S
from ringfit.units import KMH

#: A channel whose rms is below this share of its axis's median rms over the records is dead.
DEAD_REL = 1e-2
#: Samples a flat top must last to be called clipping (two runs of two also count).
CLIP_RUN = 3
#: Robust z of the derivative beyond which a sample step is an outlier.
SPIKE_Z = 12.0
#: A spike goes out and comes back within this many samples.
SPIKE_WIDTH = 4
#: Running window [samples] of the derivative's median and MAD.
SPIKE_WINDOW = 33
#: Time before the impact left out of the spike search [s] (the skip after it is the SSI's, seed §4.3).
IMPACT_GUARD_S = 0.005
#: Mains frequencies [Hz] and their relative tolerance.
MAINS_HZ = (50.0, 60.0)
MAINS_TOL = 0.004
#: A hum line stands this many times above the median power around it (±HUM_AROUND_HZ, or beyond the main
#: lobe out to twice its width where the late half is short: 0.19 s of a 0.4-s record has a 13 Hz lobe, and
#: ±15 Hz beyond it held 3 bins, too few to judge, so the hum of short records was never found).
HUM_RATIO = 50.0
HUM_AROUND_HZ = 15.0
#: A hum line keeps its amplitude over the late half within this factor.
HUM_STEADY = 1.6
#: A hum line's amplitude is at least this share of the rms of the late half (weaker lines do not matter).
HUM_SHARE = 0.2
#: Correlation below which two repeats of one angle disagree in sign.
FLIP_CORR = -0.5
#: Window after the impact [s] over which repeats are compared.
FLIP_WINDOW_S = 0.25
#: Shape check: least share of a resonance's pattern (after trimming) that one circumferential harmonic explains.
SHAPE_FIT = 0.8
#: Shape check: share of the channels per axis and resonance left out of the fit as the worst-fitting (trimmed).
SHAPE_TRIM = 0.15
#: Shape check: agreement score below which a channel reads with the wrong sign.
SHAPE_FLIP = -0.5
#: Shape check: a channel sees a resonance when its predicted value is at least this share of the pattern's rms.
SHAPE_SEEN = 0.3
#: Shape check: resonances a channel must see for its sign to be judged.
SHAPE_PEAKS = 2
#: Shape check: fewest distinct sensor angles per axis (fewer: the harmonics cannot be told apart).
SHAPE_MIN_ANGLES = 6
#: Shape check: strongest resonances of the axis looked at.
SHAPE_MAX_PEAKS = 16
#: Shape check: the force is read up to this time after the impact [s] (the hammer's contact; ``frf``'s window).
SHAPE_FORCE_S = 0.02


@dataclass
class Faults:
    """What :func:`find_faults` found and did.

    - ``acc``: the records' acceleration with hum notched and lone spikes bridged, (records, axes, samples).
    - ``use``: bool (records, axes): the channel of that record is used.
    - ``reason``: (records, axes) str, ``""`` or the fault of the channel (``dead``, ``clipped``, ``spikes``,
      ``flipped``).
    - ``hum``: (records, axes) list of the line frequencies [Hz] notched in each channel.
    - ``notes``: one-line findings.
    """

    acc: np.ndarray
    use: np.ndarray
    reason: np.ndarray
    hum: list
    notes: list = field(default_factory=list)


def impact_estimate(acc: np.ndarray, force: np.ndarray | None, threshold: float = 0.1) -> np.ndarray:
    """Sample of the impact in each record: from the force (:func:`~ringfit.targets.preprocessing.impact_indices`),
    else the largest 9-sample running median of |acc| summed over the axes (spikes do not move it)."""
    if force is not None:
        from ringfit.targets.preprocessing import impact_indices

        return impact_indices(force, threshold)
    from scipy.ndimage import median_filter

    env = median_filter(np.abs(acc).sum(axis=1), size=(1, 9), mode="nearest")
    return np.argmax(env, axis=1)


def clip_runs(x: np.ndarray, at: np.ndarray | None = None) -> tuple[int, int]:
    """``(longest, runs)``: the longest run of samples at the channel's largest or smallest value and the number
    of runs of two or more there (exact equality up to 1e-9 of the range); ``at``: take the extremes from this
    (the whole channel) instead of ``x``."""
    ref = x if at is None else at
    lo, hi = float(ref.min()), float(ref.max())
    if hi <= lo:
        return 0, 0
    tol = 1e-9 * (hi - lo)
    longest = runs = 0
    for at in (np.abs(x - hi) <= tol, np.abs(x - lo) <= tol):
        edges = np.diff(np.concatenate([[0], at.astype(np.int8), [0]]))
        length = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
        longest = max(longest, int(length.max(initial=0)))
        runs += int(np.sum(length >= 2))
    return longest, runs


def spike_segments(x: np.ndarray, exclude: tuple[int, int] = (0, 0)) -> list[tuple[int, int]]:
    """Spikes of one channel as ``[(first, last)]`` sample ranges (see the module docstring).

    ``exclude``: samples ``[a, b)`` not searched (the impact).
    """
    from scipy.ndimage import median_filter

    d = np.diff(x)
    if d.size < SPIKE_WINDOW:
        return []
    med = median_filter(d, size=SPIKE_WINDOW, mode="nearest")
    # the scale from the second difference: on a densely sampled decay the derivative is a ramp over the
    # window, whose running median follows it so closely that the derivative's own MAD is far below its noise
    dd = np.diff(d, prepend=d[0])
    dev = np.abs(dd - median_filter(dd, size=SPIKE_WINDOW, mode="nearest"))
    scale = 1.4826 * median_filter(dev, size=SPIKE_WINDOW, mode="nearest")
    floor = 1.4826 * float(np.median(dev)) * 0.1 + np.finfo(float).tiny
    z = (d - med) / np.maximum(scale, floor)
    out = np.flatnonzero(np.abs(z) > SPIKE_Z)
    edge = SPIKE_WINDOW // 2  # the running statistics are one-sided there
    out = out[((out < exclude[0]) | (out >= exclude[1])) & (out >= edge) & (out < d.size - edge)]
    segs, k = [], 0
    while k < out.size:
        i = out[k]
        back = out[(out > i) & (out <= i + SPIKE_WIDTH) & (np.sign(z[out]) == -np.sign(z[i]))]
        if back.size:
            segs.append((int(i) + 1, int(back[-1])))
            k = int(np.searchsorted(out, back[-1], side="right"))
        else:
            k += 1
    return segs


def bridge(x: np.ndarray, segs) -> np.ndarray:
    """``x`` with each sample range ``(first, last)`` replaced by the straight line between its neighbours."""
    x = x.copy()
    for a, b in segs:
        lo, hi = max(a - 1, 0), min(b + 1, x.size - 1)
        x[a:b + 1] = np.interp(np.arange(a, b + 1), [lo, hi], [x[lo], x[hi]])
    return x


def hum_lines(x: np.ndarray, fs_hz: float, start: int, f_top_hz: float) -> list[tuple[float, np.ndarray]]:
    """Mains lines of one channel: ``[(f_hz, (a_cos, a_sin))]`` fitted on the late half from ``start`` on."""
    late = x[start:]
    n = late.size
    if n / fs_hz < 0.08:  # too short to tell a line from a mode's tail
        return []
    t = (start + np.arange(n)) / fs_hz
    nfft = 4 * n
    f = np.fft.rfftfreq(nfft, 1 / fs_hz)
    p = np.abs(np.fft.rfft((late - late.mean()) * np.hanning(n), nfft)) ** 2
    width = 2.5 * fs_hz / n  # Hann main lobe and a little
    cands = []
    for base in MAINS_HZ:
        h = 1
        while h * base * (1 - MAINS_TOL) < min(f_top_hz, 0.95 * fs_hz / 2):
            fh = h * base
            h += 1
            near = np.flatnonzero(np.abs(f - fh) <= MAINS_TOL * fh + 2.5 * fs_hz / nfft)
            if near.size < 3:
                continue
            k = near[np.argmax(p[near])]
            if k in (near[0], near[-1]) or not p[k - 1] <= p[k] >= p[k + 1]:
                continue  # the slope of something else, not a line here
            ring = (np.abs(f - f[k]) <= max(HUM_AROUND_HZ, 2 * width)) & (np.abs(f - f[k]) > width)
            if ring.sum() >= 8 and p[k] >= HUM_RATIO * np.median(p[ring]):
                cands.append((float(p[k]), int(k), fh))
    picked = []  # (frequency of the peak bin, nominal harmonic)
    for _, k, fh in sorted(cands, reverse=True):  # strongest first: a weaker candidate beside it is its leakage
        if not any(abs(f[k] - g) < 2 * width for g, _ in picked):
            picked.append((float(f[k]), fh))
    if not picked:
        return []
    fr = np.array([_refine(late, t, g, fs_hz / nfft) for g, _ in picked])
    half = n // 2
    a1 = np.hypot(*_tones(late[:half], t[:half], fr)[:, :2].T)
    a2 = np.hypot(*_tones(late[half:], t[half:], fr)[:, :2].T)
    late_rms = float(np.std(late))
    keep = [i for i, (g, fh) in enumerate(picked)
            if abs(fr[i] - fh) <= MAINS_TOL * fh + 0.5 * fs_hz / n  # else slid off: leakage of a stronger line
            and 1 / HUM_STEADY <= a1[i] / max(a2[i], np.finfo(float).tiny) <= HUM_STEADY  # a mode's tail decays
            and 0.5 * (a1[i] + a2[i]) >= HUM_SHARE * late_rms]  # a visible share of what the decay leaves
    if not keep:
        return []
    fr = fr[keep]
    coef = _tones(late, t, fr)
    return [(float(g), c) for g, c in zip(fr, coef)]


def _tones(x: np.ndarray, t: np.ndarray, f_hz: np.ndarray) -> np.ndarray:
    """Least-squares (cos, sin) amplitudes of tones at ``f_hz`` (with a constant) in x(t): (tones, 2)."""
    w = 2 * np.pi * np.asarray(f_hz)[None, :] * t[:, None]
    design = np.concatenate([np.cos(w), np.sin(w), np.ones((t.size, 1))], axis=1)
    c = np.linalg.lstsq(design, x, rcond=None)[0]
    k = len(f_hz)
    return np.stack([c[:k], c[k:2 * k]], axis=1)


def _refine(x: np.ndarray, t: np.ndarray, f0: float, df: float) -> float:
    """The frequency [Hz] of a line near ``f0``: the peak of the Hann-windowed spectrum of x(t) on a grid of
    ``df``/20 over ±``df``, refined by a parabola through the top three points of its log."""
    grid = f0 + df * np.linspace(-1.0, 1.0, 41)
    xw = (x - x.mean()) * np.hanning(x.size)
    p = np.log(np.abs(np.exp(-2j * np.pi * grid[:, None] * t[None, :]) @ xw) ** 2 + np.finfo(float).tiny)
    k = int(np.clip(np.argmax(p), 1, grid.size - 2))
    a, b, c = p[k - 1], p[k], p[k + 1]
    den = a - 2 * b + c
    return float(grid[k] + (0.5 * (a - c) / den if den < 0 else 0.0) * (grid[1] - grid[0]))


def _nominal(f_hz: float) -> float:
    """The mains harmonic h × 50 or h × 60 Hz nearest a line."""
    return min((round(f_hz / b) * b for b in MAINS_HZ), key=lambda x: abs(x - f_hz))


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    den = np.sqrt(np.sum(a * a) * np.sum(b * b))
    return float(np.sum(a * b) / den) if den > 0 else 0.0


def impact_spectra(acc: np.ndarray, force: np.ndarray, impact: np.ndarray, fs_hz: float, *, pre_s: float = 0.002,
                   force_s: float = SHAPE_FORCE_S) -> tuple[np.ndarray, np.ndarray]:
    """Accelerance spectra of each record and axis, from ``pre_s`` before its impact to the common end.

    ``H = X·conj(F) / (|F|² + ε)`` with ``ε`` = 10⁻³ of the largest ``|F|²`` (a soft hammer tip's spectral zeros
    do not blow up); the force is read from ``pre_s`` before the impact to ``force_s`` after it, its pre-impact
    mean removed. Dividing by the force takes out each record's time origin and impact strength.

    **Returns:** ``(f_hz (F,), H (records, axes, F))``, the spectra zero-padded to twice the window.
    """
    r, a, s = acc.shape
    pre = int(round(pre_s * fs_hz))
    start = np.maximum(np.asarray(impact, dtype=np.int64) - pre, 0)
    n = int(s - start.max())
    x = np.stack([acc[i, :, start[i]:start[i] + n] for i in range(r)])
    fo = np.stack([force[i, start[i]:start[i] + n] - np.mean(force[i, :max(int(start[i]), 1)]) for i in range(r)])
    fo = fo * (np.arange(n) <= pre + int(round(force_s * fs_hz)))
    nfft = 2 * n
    fspec = np.fft.rfft(fo, nfft, axis=-1)
    p = np.abs(fspec) ** 2
    eps = 1e-3 * p.max(axis=-1, keepdims=True) + np.finfo(float).tiny
    h = np.fft.rfft(x, nfft, axis=-1) * (np.conj(fspec) / (p + eps))[:, None, :]
    return np.fft.rfftfreq(nfft, 1 / fs_hz), h


def _harmonics(theta: np.ndarray, n: int) -> np.ndarray:
    """Columns ``cos nθ, sin nθ`` (n ≥ 1) or ``1`` (n = 0) at the angles ``theta`` [rad] (docs/physics.md §9)."""
    return np.ones((theta.size, 1)) if n == 0 else np.stack([np.cos(n * theta), np.sin(n * theta)], axis=1)


def shape_scores(f_hz: np.ndarray, h: np.ndarray, theta: np.ndarray, ok: np.ndarray, band: tuple[float, float]
                 ) -> tuple[np.ndarray, np.ndarray]:
    """How well each channel's sign agrees with the circumferential pattern of its axis at the resonances.

    Per axis, at each of the :data:`SHAPE_MAX_PEAKS` strongest peaks of ``Σ_records |H|²`` in ``band``: the
    channels' values ``z_r`` are one circumferential harmonic ``c·cos nθ + s·sin nθ`` of a ring mode
    (docs/physics.md §9, sign flips), n the harmonic that explains most of them after the worst-fitting
    :data:`SHAPE_TRIM` share is left out; a peak where it explains less than :data:`SHAPE_FIT` is passed over.
    Each channel's value is predicted from the others (leave-one-out, ``ẑ_r``), and

    ``score_r = Σ_peaks Re(conj(ẑ_r) z_r) / Σ_peaks |ẑ_r| |z_r|``

    over the peaks where the channel is not near a node (``|ẑ_r|`` ≥ :data:`SHAPE_SEEN` × the pattern's rms):
    about +1 for a channel that reads with the ring, −1 for one that reads with the wrong sign.

    **Arguments:** ``h`` (records, axes, F) from :func:`impact_spectra`; ``theta`` (records,) [rad]; ``ok`` bool
    (records, axes): the channels taken into account.

    **Returns:** ``(score, seen)`` (records, axes): NaN where fewer than :data:`SHAPE_PEAKS` peaks judge the
    channel (or its axis has fewer than :data:`SHAPE_MIN_ANGLES` angles), and the number of peaks that do.
    """
    from scipy.signal import find_peaks

    r, a, _ = h.shape
    sel = np.flatnonzero((f_hz >= band[0]) & (f_hz <= band[1]))
    score = np.full((r, a), np.nan)
    seen = np.zeros((r, a), dtype=np.int64)
    for j in range(a):
        rows = np.flatnonzero(ok[:, j])
        th = theta[rows]
        angles = np.unique(np.round(np.mod(th, 2 * np.pi), 9)).size
        if angles < SHAPE_MIN_ANGLES or sel.size < 3:
            continue
        n_max = (angles - 2) // 2  # harmonics the angles can tell apart, with one to spare for the left-out one
        hj = h[rows, j]
        power = 10 * np.log10(np.maximum(np.sum(np.abs(hj[:, sel]) ** 2, axis=0), np.finfo(float).tiny))
        pk, _ = find_peaks(power, prominence=3.0)
        pk = sel[pk[np.argsort(power[pk])[::-1][:SHAPE_MAX_PEAKS]]]
        num, den, cnt = np.zeros(rows.size), np.zeros(rows.size), np.zeros(rows.size, dtype=np.int64)
        trim = max(1, int(round(SHAPE_TRIM * rows.size)))
        for k in pk:
            z = hj[:, k]
            best = None
            for n in range(n_max + 1):
                basis = _harmonics(th, n)
                res = np.abs(z - basis @ np.linalg.lstsq(basis, z, rcond=None)[0])
                keep = np.ones(rows.size, bool)
                keep[np.argsort(res)[-trim:]] = False
                coef = np.linalg.lstsq(basis[keep], z[keep], rcond=None)[0]
                explained = 1 - np.sum(np.abs(z[keep] - basis[keep] @ coef) ** 2) / max(
                    float(np.sum(np.abs(z[keep]) ** 2)), np.finfo(float).tiny)
                if best is None or explained > best[0]:
                    best = (explained, basis, keep, coef)
            explained, basis, keep, coef = best
            if explained < SHAPE_FIT:
                continue
            q, _ = np.linalg.qr(basis[keep])
            lev = np.sum(q**2, axis=1)
            if lev.max() >= 0.99:
                continue  # a channel the pattern hinges on: no prediction without it
            pred = basis @ coef  # the trimmed channels: predicted by the kept ones
            zk = z[keep]
            pred[keep] = (q @ (q.T @ zk) - lev * zk) / (1 - lev)  # leave-one-out through the hat matrix
            visible = np.abs(pred) >= SHAPE_SEEN * np.sqrt(np.mean(np.abs(pred) ** 2))
            num += np.where(visible, np.real(np.conj(pred) * z), 0.0)
            den += np.where(visible, np.abs(pred) * np.abs(z), 0.0)
            cnt += visible
        score[rows, j] = np.where(cnt >= SHAPE_PEAKS, num / np.where(den > 0, den, 1.0), np.nan)
        seen[rows, j] = cnt
    return score, seen


def shape_flips(f_hz: np.ndarray, h: np.ndarray, theta: np.ndarray, ok: np.ndarray, band: tuple[float, float],
                rounds: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Channels whose sign contradicts the ring's mode shapes (:func:`shape_scores` below :data:`SHAPE_FLIP`).

    Found in rounds: the channels found are turned round and the scores taken again (several flipped channels
    spoil the patterns the others are judged by), until no new one is found.

    **Returns:** ``(flipped, score)``: bool (records, axes) and the last round's scores with the flipped
    channels turned round (so a flipped channel scores about +1 there).
    """
    h = np.array(h)
    flipped = np.zeros(ok.shape, dtype=bool)
    for _ in range(rounds):
        score, _ = shape_scores(f_hz, h, theta, ok, band)
        new = (score < SHAPE_FLIP) & ~flipped & ok
        if not new.any():
            return flipped, score
        flipped |= new
        h[new] *= -1
    return flipped, shape_scores(f_hz, h, theta, ok, band)[0]


def find_faults(acc: np.ndarray, angle_deg: np.ndarray, axes, fs_hz: float, impact: np.ndarray, *,
                f_max_hz: float = 400.0, skip_s: float = SKIP_AFTER_IMPACT_S, used_from_s: float = 0.0,
                force: np.ndarray | None = None) -> Faults:
    """Run every check of the module docstring on offset-free records and repair or mark what is found.

    **Arguments:** ``acc`` (records, axes, samples) [m/s²], offsets removed; ``angle_deg`` (records,);
    ``axes`` names; ``impact`` (records,) sample of each impact; ``f_max_hz`` the top of the band (hum lines
    are looked for up to twice it); ``skip_s`` the time after the impact left out of the spike search;
    ``used_from_s`` the time after the impact from which the samples are used (SSI: its skip): clipping
    that ends before it is said but harmless; ``force`` (records, samples) [N] the hammer's force, for the
    sign check against the ring's mode shapes (without it, only repeats of an angle are compared).
    """
    acc = np.array(acc, dtype=np.float64)
    r, a, s = acc.shape
    reason = np.full((r, a), "", dtype=object)
    impact = np.asarray(impact, dtype=np.int64)
    angles, group = np.unique(np.round(np.asarray(angle_deg, dtype=np.float64), 9), return_inverse=True)
    notes = []

    def label(i, j):
        return f"record {i} ({angle_deg[i]:g}° {axes[j]})"

    def say(what, cells, action):
        if cells:
            shown = ", ".join(label(i, j) for i, j in cells[:4]) + (f" and {len(cells) - 4} more"
                                                                   if len(cells) > 4 else "")
            notes.append(f"{len(cells)} channel(s) {what}: {shown}; {action}")

    # dead
    rms = np.sqrt(np.mean(acc**2, axis=-1))
    typical = np.median(rms, axis=0)
    dead = (rms <= DEAD_REL * typical[None, :]) & (typical[None, :] > 0)
    reason[dead] = "dead"
    # clipped
    used = impact + int(round(used_from_s * fs_hz))  # clipping before this sample is never read
    clipped_early = []
    for i, j in zip(*np.nonzero(~dead)):
        longest, runs = clip_runs(acc[i, j])
        if longest >= CLIP_RUN or runs >= 2:
            if clip_runs(acc[i, j, used[i]:], at=acc[i, j])[0] >= 2:  # flat tops among the samples used
                reason[i, j] = "clipped"
            else:
                clipped_early.append((i, j))
    # spikes
    guard, skip = int(round(IMPACT_GUARD_S * fs_hz)), int(round(skip_s * fs_hz)) + 1
    spikes = {}
    for i in range(r):
        for j in range(a):
            if reason[i, j] in ("dead", "clipped"):
                continue
            segs = spike_segments(acc[i, j], (max(0, impact[i] - guard), impact[i] + skip))
            if segs:
                spikes[(i, j)] = segs
                reason[i, j] = "spikes"
                acc[i, j] = bridge(acc[i, j], segs)  # before the hum is fitted: a spike train has mains-like lines
    # mains hum: notched on every live channel where it stands out
    hum = [[[] for _ in range(a)] for _ in range(r)]
    t = np.arange(s) / fs_hz
    peak_hum = 0.0
    for i in range(r):
        start = impact[i] + (s - impact[i]) // 2
        for j in range(a):
            if reason[i, j] == "dead":
                continue
            for fr, (ac, as_) in hum_lines(acc[i, j], fs_hz, int(start), 2.0 * f_max_hz):
                acc[i, j] -= ac * np.cos(2 * np.pi * fr * t) + as_ * np.sin(2 * np.pi * fr * t)
                hum[i][j].append(fr)
                peak_hum = max(peak_hum, float(np.hypot(ac, as_)))
    # sign flips among the repeats of each angle
    n_win = int(min(FLIP_WINDOW_S * fs_hz, s - impact.max()))
    flipped, undecided = [], []
    if n_win > 16:
        win = np.stack([acc[i, :, impact[i]:impact[i] + n_win] for i in range(r)])  # (records, axes, n_win)
        ok = reason == ""
        for g in range(angles.size):
            members = np.flatnonzero(group == g)
            for j in range(a):
                rep = [i for i in members if ok[i, j]]
                if len(rep) < 2:
                    continue
                c = np.array([[_corr(win[p, j], win[q, j]) for q in rep] for p in rep])
                if len(rep) >= 3:
                    med = np.array([np.median(np.delete(c[k], k)) for k in range(len(rep))])
                    flipped += [(rep[k], j) for k in np.flatnonzero(med < FLIP_CORR)]
                elif c[0, 1] < FLIP_CORR:  # two repeats: which one is flipped cannot be told
                    undecided += [(p, j) for p in rep]
    for i, j in flipped:
        reason[i, j] = "flipped"
    # sign flips against the ring's mode shapes: any number of repeats, and which of two disagreeing ones
    shape_out, shape_back = [], []
    if force is not None and n_win > 16:
        judged = reason == ""  # the undecided pairs among them
        f_hz, spec = impact_spectra(acc, np.asarray(force, dtype=np.float64), impact, fs_hz)
        bad, score = shape_flips(f_hz, spec, np.deg2rad(np.asarray(angle_deg, dtype=np.float64)), judged,
                                 (min(5.0, 0.5 * f_max_hz), f_max_hz))
        pairs = {}
        for i, j in undecided:
            pairs.setdefault((group[i], j), []).append(i)
        for (_, j), (p, q) in pairs.items():
            if bad[p, j] != bad[q, j] and score[q if bad[p, j] else p, j] >= -SHAPE_FLIP:  # the shapes tell
                undecided.remove((p, j))
                undecided.remove((q, j))
        still = set(undecided)
        for i, j in zip(*np.nonzero(bad & judged)):
            if (i, j) in still:
                continue
            others = [k for k in np.flatnonzero(group == group[i])
                      if k != i and judged[k, j] and (k, j) not in still and not bad[k, j]]
            if others:
                shape_out.append((int(i), int(j)))
            else:  # the only usable repeat of its angle (or all of them read the other way): turned round
                acc[i, j] = -acc[i, j]
                shape_back.append((int(i), int(j)))
    for i, j in undecided + shape_out:
        reason[i, j] = "flipped"
    # actions
    use = reason == ""
    bridged = []
    for (i, j), segs in spikes.items():
        clean_repeat = any(use[k, j] for k in np.flatnonzero(group == group[i]) if k != i)
        if not clean_repeat:
            acc[i, j] = bridge(acc[i, j], segs)
            use[i, j] = True
            bridged.append((i, j))
    lost = []
    for g in range(angles.size):
        members = np.flatnonzero(group == g)
        for j in range(a):
            if not use[members, j].any():
                lost.append(f"{angles[g]:g}° {axes[j]}")
    n_hum = sum(bool(hum[i][j]) for i in range(r) for j in range(a))
    if n_hum:
        nominal = sorted({_nominal(fr) for row in hum for cell in row for fr in cell})
        shown = ", ".join(f"{x:g}" for x in nominal[:8]) + (" …" if len(nominal) > 8 else "")
        notes.append(f"mains hum (lines at {shown}"
                     f" Hz, narrow and not decaying, up to {peak_hum:.3g} m/s²) in {n_hum} of {r * a} channels: "
                     "notched (each channel's steady tone subtracted)")
    say("dead (rms below 1 % of the axis's median)", [tuple(c) for c in np.argwhere(reason == "dead")],
        "left out of their record")
    say("clipped (flat tops at the range)", [tuple(c) for c in np.argwhere(reason == "clipped")],
        "left out of their record")
    say("clipped only before the samples used (within the skip after the impact)", clipped_early, "kept")
    spiky = sorted(spikes)
    if spiky:
        n_seg = sum(len(v) for v in spikes.values())
        say(f"with spikes ({n_seg} found by the robust z of the derivative)", spiky,
            "left out of their record where another repeat of the angle is clean"
            + (f", bridged by straight lines in {len(bridged)} without one" if bridged else ""))
    say("sign-flipped (anti-correlated with the other repeats of the angle)", flipped, "left out of their record")
    say("of repeats that disagree in sign (which one is flipped cannot be told)", undecided,
        "left out of their record")
    said = "sign-flipped against the ring's mode shapes (the circumferential harmonic of the other channels " \
           "at each resonance predicts the other sign)"
    say(said, shape_out, "left out of their record (another repeat of the angle reads right)")
    say(said, shape_back, "turned round (no repeat of the angle reads right)")
    if lost:
        notes.append(f"no usable repeat left for {len(lost)} channel(s): {', '.join(lost[:6])}"
                     f"{' …' if len(lost) > 6 else ''}; left out")
    return Faults(acc, use, reason, hum, notes)


def repair_records(records, *, threshold: float = 0.1, f_max_hz: float = 400.0, skip_s: float = SKIP_AFTER_IMPACT_S,
                   used_from_s: float = 0.0):
    """:func:`find_faults` on :class:`~ringfit.io.records.Records` whose offsets are removed
    (:func:`~ringfit.targets.quality.clean_records`).

    **Returns:** ``(records, use, notes, lines_hz)``: the records with hum notched and lone spikes bridged, the
    bool ``(records, axes)`` mask of the channels to use, the one-line notes and the notched mains lines [Hz]
    (:func:`hum_frequencies`).
    """
    from dataclasses import replace

    impact = impact_estimate(records.acc, records.force, threshold)
    found = find_faults(records.acc, records.sensor_angle_deg, records.axes, records.fs_hz, impact,
                        f_max_hz=f_max_hz, skip_s=skip_s, used_from_s=used_from_s, force=records.force)
    acc = found.acc
    if any(cell for row in found.hum for cell in row):  # the offsets were taken with the hum in: again without
        from ringfit.targets.quality import remove_offsets

        acc = remove_offsets(acc, impact if records.force is not None else None)[0]
    return replace(records, acc=acc), found.use, found.notes, hum_frequencies(found.hum)


def hum_frequencies(hum, min_share: float = 0.25) -> list[float]:
    """The notched lines [Hz] that a mode table must beware of: per mains harmonic notched in at least
    ``min_share`` of the channels (a line in a few channels does not make a stable pole), the median of the
    fitted frequencies."""
    per = {}
    cells = 0
    for row in hum:
        for cell in row:
            cells += 1
            for fr in cell:
                per.setdefault(_nominal(fr), []).append(fr)
    return [float(np.median(v)) for _, v in sorted(per.items()) if len(v) >= min_share * cells]


def on_notched_line(freq_hz: float, lines_hz, duration_s: float) -> float | None:
    """The notched line a row sits on — within 0.5 % of it or one frequency resolution ``1/duration_s`` of the
    records, whichever is wider — or None. What the notch leaves of a strong hum can still form a stable pole or
    an FRF peak there; such a row is not shown to be a mode."""
    for line in lines_hz:
        if abs(freq_hz - line) <= max(0.005 * line, 1.0 / duration_s):
            return float(line)
    return None


# ROLLING_RADIUS_M (the rolling radii a road tyre can have) and RATE_TOL (the relative disagreement of two rates
# called a contradiction) are the one consistency layer's (ringfit.io.conditions), imported above


def sample_rate_note(rotation_hz: float, fs_hz: float, condition: dict) -> str | None:
    """A one-line note when the sampling rate contradicts the encoder, else None.

    ``rotation_hz`` is the encoder's revolutions divided by the recording's length at ``fs_hz``. With a stated
    ``rotation_hz`` in ``condition`` (the rig's own tachometer) the two must agree within :data:`RATE_TOL`;
    with only ``speed_kmh`` the rolling radius ``V / (2π·rotation_hz)`` they imply must lie in
    :data:`ROLLING_RADIUS_M`. A wrong ``fs_hz`` scales the encoder's rate by the same factor as every
    frequency found in the recording, so it is worth a warning before anything is identified.
    """
    if not (np.isfinite(rotation_hz) and rotation_hz > 0):
        return None
    stated = float(condition.get("rotation_hz") or 0.0)
    if stated > 0:
        ratio = rotation_hz / stated
        if abs(ratio - 1) > RATE_TOL:
            return (f"the encoder turns {rotation_hz:.4g} times a second at the stated sampling rate {fs_hz:g} Hz, "
                    f"but the recording states rotation_hz = {stated:g}: the sampling rate contradicts the encoder "
                    f"(they agree at {fs_hz / ratio:.6g} Hz); every frequency found is off by {ratio:.4g}×")
        return None
    speed = float(condition.get("speed_kmh") or 0.0)
    if speed > 0:
        radius = speed * KMH / (2 * np.pi * rotation_hz)
        lo, hi = ROLLING_RADIUS_M
        if not lo <= radius <= hi:
            return (f"the encoder turns {rotation_hz:.4g} times a second at the stated sampling rate {fs_hz:g} Hz, "
                    f"which at speed_kmh = {speed:g} means a rolling radius of {radius:.3g} m (a tyre has "
                    f"{lo:g}–{hi:g} m): the sampling rate (or the speed) contradicts the encoder")
    return None


def trigger_rate_note(interval_s: float, fs_hz: float, condition: dict) -> str | None:
    """A one-line note when the sampling rate contradicts the cleat trigger's spacing, else None.

    The hall (cleat) trigger fires once per drum revolution, so its median spacing ``interval_s`` (counted in
    samples, divided by the stated ``fs_hz``) must equal ``π·drum_diameter_m / V`` at the stated ``speed_kmh``
    within :data:`RATE_TOL` (a drum holds its set speed to well under that; a
    25 kHz recording said to be 25.6 kHz is 2.4 % off; docs/physics.md §9). Without both keys (a flat track, no speed) nothing is said.
    A wrong ``fs_hz`` scales every time and frequency found in the recording by the same factor.
    """
    drum = float(condition.get("drum_diameter_m") or 0.0)
    speed = float(condition.get("speed_kmh") or 0.0)
    if not (drum > 0 and speed > 0 and np.isfinite(interval_s) and interval_s > 0):
        return None
    expected = np.pi * drum / (speed * KMH)
    if abs(interval_s / expected - 1) <= RATE_TOL:
        return None
    return (f"the cleat trigger fires every {1e3 * interval_s:.5g} ms at the stated sampling rate {fs_hz:g} Hz, but "
            f"one revolution of the {drum:g} m drum at speed_kmh = {speed:g} takes {1e3 * expected:.5g} ms: the "
            f"sampling rate (or the speed) contradicts the trigger spacing (they agree at "
            f"{fs_hz * interval_s / expected:.6g} Hz); every frequency found is off by {expected / interval_s:.4g}×")


# --------------------------------------------------------------------------- timing faults: stalls and drift

#: A stall is said once this share of a record set's samples repeats the frame before it.
STALL_MIN_SHARE = 0.002
#: The verdict of :func:`stall_verdict` below the first value: the repeats were inserted (the stream stalled and
#: resumed where it was: delete them); above the second: they replaced samples (the stream held its last value
#: and lost what came meanwhile: bridge them); between, the data cannot tell and the table is not credible.
STALL_SPLIT = (0.35, 0.65)
#: Least ratio of the typical step over a run's length + 1 samples to the one-sample step for the verdict to
#: count (below it noise makes the steps and cannot tell inserted repeats from held ones).
STALL_MIN_SPREAD = 1.2
#: A record set whose share of stalled samples exceeds this is ruined: the table is not credible.
STALL_RUINED = 0.25
#: Half-width [samples] of the window over which the typical step beside a stall is taken.
STALL_WINDOW = 16



def stalled_frames(acc: np.ndarray) -> np.ndarray:
    """Samples of one record that repeat the sample before exactly on every live axis: bool ``(samples,)``.

    ``acc`` (axes, samples). A stream that stalls repeats the whole frame; an analog channel never does (a
    quantised one can, where the signal is below a step of the converter: such a repeat is not counted unless
    the step after it, on some axis, is at least 4 of that axis's smallest non-zero steps, and a record set is
    called stalled only with far more repeats than the converter makes by chance, :func:`chance_repeats`).
    Frames that read exactly zero on every axis (a noise-free pre-trigger) are not stalls.
    """
    acc = np.asarray(acc, dtype=np.float64)
    live = acc.std(axis=-1) > 0
    if not live.any() or acc.shape[-1] < 3:
        return np.zeros(acc.shape[-1], dtype=bool)
    x = acc[live]
    d = np.diff(x, axis=-1)
    same = np.all(d == 0, axis=0) & np.any(x[:, 1:] != 0, axis=0)
    if not same.any():
        return np.zeros(acc.shape[-1], dtype=bool)
    ad = np.abs(d)
    q = np.array([row[row > 0].min() if (row > 0).any() else np.inf for row in ad])  # the converter's step
    after = np.concatenate([ad[:, 1:], np.zeros((ad.shape[0], 1))], axis=1)  # the step after sample k+1
    # the step that ends a run: the next one that is not zero
    k = np.flatnonzero(same)
    out = np.zeros(acc.shape[-1], dtype=bool)
    run_start = 0
    while run_start < k.size:
        run_end = run_start
        while run_end + 1 < k.size and k[run_end + 1] == k[run_end] + 1:
            run_end += 1
        last = k[run_end]
        step = after[:, last] if last < ad.shape[1] else np.zeros(ad.shape[0])
        if np.any(step >= 4 * q):
            out[k[run_start:run_end + 1] + 1] = True
        run_start = run_end + 1
    return out


def chance_repeats(acc: np.ndarray) -> float:
    """How many frames of one record (axes, samples) would repeat the frame before exactly by chance on a
    quantised converter: ``Σ_k Π_j min(1, q_j / (σ_jk √(2π)))`` with ``q_j`` the axis's smallest non-zero step
    (the converter's step) and ``σ_jk`` the local spread of its steps (running median of ``|Δx|`` over
    :data:`SPIKE_WINDOW` samples / 0.674). Float data (no quantisation) give ≈ 0."""
    from scipy.ndimage import median_filter

    acc = np.asarray(acc, dtype=np.float64)
    live = acc.std(axis=-1) > 0
    if not live.any() or acc.shape[-1] < 3:
        return 0.0
    ad = np.abs(np.diff(acc[live], axis=-1))
    p = np.ones(ad.shape[1])
    for row in ad:
        pos = row[row > 0]
        if not pos.size:
            continue
        q = float(pos.min())
        sigma = median_filter(row, size=SPIKE_WINDOW, mode="nearest") / 0.674
        with np.errstate(over="ignore"):  # a flat stretch: a repeat there is certain (1)
            p *= np.minimum(1.0, q / np.maximum(sigma * np.sqrt(2 * np.pi), np.finfo(float).tiny))
    return float(p.sum())


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[(first, last)]`` of the runs of True in ``mask``."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), (np.flatnonzero(edges == -1) - 1).tolist()))


def stall_verdict(acc: np.ndarray, stalls: np.ndarray) -> tuple[float, float]:
    """Were the repeats inserted or held? ``(u, spread)`` from the step that ends each run.

    Inserted repeats (the stream resumed where it stopped) end in an ordinary one-sample step; held ones (the
    stream kept its last value and lost the samples meanwhile) in a step over the run's length + 1 samples.
    Over the loudest quarter of the runs (by the typical step beside them: where the signal, not the noise,
    makes the steps), with ``J`` the steps that end the runs, ``T₁`` the typical one-sample step and ``T_L`` the
    typical step over L + 1 samples beside each run (medians over ±:data:`STALL_WINDOW` samples of steps
    between samples that are not repeats), ``u = ln(ΣJ/ΣT₁) / ln(ΣT_L/ΣT₁)``: ≈ 0 inserted, ≈ 1 held.
    ``spread = ΣT_L/ΣT₁``; near 1 (noise makes the steps) ``u`` tells nothing. nan, nan without a usable run.
    """
    jump, t1, tl = [], [], []
    for i in range(acc.shape[0]):
        x, mask = acc[i], stalls[i]
        step = np.linalg.norm(np.diff(x, axis=-1), axis=0)  # step from sample k to k + 1
        good = ~mask
        for a, b in _runs(mask):
            if b + 1 >= x.shape[-1]:
                continue
            length = b - a + 1
            lo, hi = max(a - 1 - STALL_WINDOW, 0), min(b + 1 + STALL_WINDOW, x.shape[-1] - 1)
            j1 = np.arange(lo, hi)
            j1 = j1[good[j1] & good[j1 + 1]]
            jl = np.arange(lo, max(hi - length, lo))
            jl = jl[good[jl] & good[jl + length + 1]]
            if not (j1.size and jl.size):
                continue
            jump.append(step[b])
            t1.append(np.median(step[j1]))
            tl.append(np.median(np.linalg.norm(x[:, jl + length + 1] - x[:, jl], axis=0)))
    if not jump:
        return float("nan"), float("nan")
    jump, t1, tl = map(np.asarray, (jump, t1, tl))
    loud = t1 >= np.quantile(t1, 0.75)
    j, a, b = float(jump[loud].sum()), float(t1[loud].sum()), float(tl[loud].sum())
    if not (j > 0 and a > 0 and b > a):
        return float("nan"), b / a if a > 0 else float("nan")
    return float(np.log(j / a) / np.log(b / a)), b / a


def repair_stalls(acc: np.ndarray, force: np.ndarray | None, fs_hz: float):
    """Find stalls in impact records and mend them (module docstring of :func:`repair_timing`).

    **Returns:** ``(acc, force, notes, credible)``; the arrays unchanged (and no note) without a stall.
    """
    r, a, s = acc.shape
    stalls = np.stack([stalled_frames(acc[i]) for i in range(r)])
    share = float(stalls.mean())
    if share < STALL_MIN_SHARE:
        return acc, force, [], True
    chance = sum(chance_repeats(acc[i]) for i in range(r))
    if stalls.sum() <= 4 * chance + 5:  # no more repeats than a quantised converter makes by chance
        return acc, force, [], True
    u, spread = stall_verdict(acc, stalls)
    runs = sum(len(_runs(m)) for m in stalls)
    bad = int(stalls.any(axis=1).sum())
    what = (f"stalled stream: {int(stalls.sum())} of {stalls.size} samples ({100 * share:.1f} %) repeat the frame "
            f"before them exactly on every axis, in {runs} run(s) in {bad} of {r} records (the steps that end the "
            f"runs sit {u:.2f} of the way from a one-sample step to a step over the run")
    credible = share <= STALL_RUINED
    tells = np.isfinite(u) and spread >= STALL_MIN_SPREAD
    if tells and u < STALL_SPLIT[0]:
        keep = ~stalls
        n = int(keep.sum(axis=1).min())
        acc = np.stack([acc[i][:, keep[i]][:, :n] for i in range(r)])
        if force is not None:
            force = np.stack([force[i][keep[i]][:n] for i in range(r)])
        what += (f": the stream resumed where it stopped); the repeats deleted (the time base restored) and the "
                 f"records cut to a common {n} samples ({n / fs_hz:.3g} s)")
    elif tells and u > STALL_SPLIT[1]:
        acc = acc.copy()
        force = None if force is None else force.copy()
        for i in range(r):
            segs = _runs(stalls[i])
            for j in range(a):
                acc[i, j] = bridge(acc[i, j], segs)
            if force is not None:
                force[i] = bridge(force[i], segs)
        what += ": the stream held its last value and lost the samples meanwhile); the held samples bridged by " \
                "straight lines"
    else:
        credible = False
        what += ": whether the repeats were inserted or held the data cannot tell); left as they are"
    if not credible:
        what += "; the table is not credible (too much of the time base is unknown)" \
            if share > STALL_RUINED else "; the table is not credible"
    return acc, force, [what], credible


def repair_timing(records):
    """Timing faults of impact :class:`~ringfit.io.records.Records`, before anything else is done to them.

    - **stalled stream**: runs of samples that repeat the frame before them exactly on every axis
      (:func:`stalled_frames`). Whether the repeats were *inserted* (the stream stopped and resumed where it
      was: every later sample is late by the run's length, every frequency read low) or *held* (the stream
      kept its last value and lost what came meanwhile) the data tell by the step that ends each run
      (:func:`stall_verdict`): inserted repeats are deleted (the time base is restored; the records are cut
      to a common length), held ones bridged by straight lines. Where the steps cannot tell
      (:data:`STALL_SPLIT`, :data:`STALL_MIN_SPREAD`) or more than :data:`STALL_RUINED` of the samples
      stalled, the table is not credible.

    The reader's own findings (``records.notes``: dropped samples filled on the time grid, docs/formats.md
    §17.3) come first in the notes.

    **Returns:** ``(records, notes, credible)``.
    """
    from dataclasses import replace

    acc, force, notes, credible = repair_stalls(records.acc, records.force, records.fs_hz)
    if notes:
        records = replace(records, acc=acc, force=force)
    return records, list(getattr(records, "notes", [])) + notes, credible


class EncoderTiming:
    """Timing faults of a continuous recording, counted chunk by chunk from its unwrapped encoder angle and its
    acceleration (:meth:`add`), said by :meth:`note`.

    - **stalled** samples: the encoder's angle and every acceleration axis repeat the sample before exactly (the
      stream repeated a frame; repeats a quantised converter makes by chance, :func:`chance_repeats`, allowed
      four times over);
    - **dropped** samples: the angle advances by ``k ≥ 2`` typical steps (the chunk's median step) at once,
      ``k − 1`` samples lost, where the steps are steady (the 75th percentile within 1.2× the 10th: a coarse
      encoder's steps alternate between multiples of its resolution and tell nothing).

    A stream that held its value while it stalled shows both (the held run, then a jump over it), and the
    count of samples the time really covers, ``samples − stalled + dropped``, is right either way.
    """

    def __init__(self):
        self.samples = self.stalled = self.dropped = self.jumps = 0
        self.chance = 0.0
        self.prev = None  # (angle, acc frame) of the last sample of the previous chunk

    def add(self, angle_deg: np.ndarray, acc: np.ndarray) -> None:
        """Take the next chunk of a continuous recording (encoder angle in degrees, ``(k, 3)`` acceleration)."""
        phi = np.asarray(angle_deg, dtype=np.float64)
        x = np.asarray(acc, dtype=np.float64)
        if self.prev is not None:
            phi = np.concatenate([[self.prev[0]], phi])
            x = np.concatenate([self.prev[1][:, None], x], axis=1)
        self.samples += int(np.asarray(angle_deg).size)
        self.prev = (float(phi[-1]), x[:, -1].copy())
        if phi.size < 3:
            return
        d = np.diff(phi)
        same = (d == 0) & np.all(np.diff(x, axis=1) == 0, axis=0)
        self.stalled += int(same.sum())
        if same.sum() >= STALL_MIN_SHARE * d.size:  # the chance count costs a running median: only when it matters
            self.chance += chance_repeats(np.vstack([x, phi[None]]))
        ad = np.abs(d[d != 0])
        if ad.size < 16:
            return
        lo, step, hi = np.quantile(ad, [0.1, 0.5, 0.75])
        if hi > 1.2 * lo:  # a coarse (or unsteady) encoder: its steps vary too much to see a lost sample
            return
        k = np.rint(np.abs(d) / step)
        jump = (k >= 2) & (np.abs(np.abs(d) - k * step) <= 0.25 * step) & (k <= 64)
        self.jumps += int(jump.sum())
        self.dropped += int(np.sum(k[jump] - 1))

    @property
    def stall_found(self) -> bool:
        return self.stalled >= STALL_MIN_SHARE * max(self.samples, 1) and self.stalled > 4 * self.chance + 5

    @property
    def covered(self) -> int:
        """Samples' worth of time the recording covers: ``samples − stalled + dropped`` (as found)."""
        return self.samples - (self.stalled if self.stall_found else 0) + self.dropped

    def note(self) -> str | None:
        """One line when a stall or dropped samples were found, else None."""
        parts = []
        if self.stall_found:
            parts.append(f"{self.stalled} samples repeat the frame before them exactly, the encoder's angle included "
                         "(a stalled stream)")
        if self.dropped:
            parts.append(f"{self.dropped} samples dropped (the encoder advances by more than one step at once at "
                         f"{self.jumps} place(s))")
        if not parts:
            return None
        return (f"timing faults: {' and '.join(parts)}; the profile bins by the encoder's angle and is not moved, "
                f"and the rotation rate is counted over the {self.covered} samples' time the recording really "
                f"covers, not its {self.samples}")
