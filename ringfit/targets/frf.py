"""FRF path: H1 and coherence over repeated impacts, peak picking, half-power damping (seed §2.2–2.3).

- :func:`h1_coherence` — ``H1 = S_FX / S_FF`` and ``Γ = √(|S_FX|² / (S_XX S_FF))``
  (seed eq. 1a–b) with the spectra averaged over the impacts of one sensor angle.
- :func:`reject_impacts` — drop impacts that spoil the coherence: while the
  band-mean coherence is below ``min_coherence`` and more than two impacts
  remain, remove the impact whose removal raises it most (the source
  discarded "excitation signals differing too much").
- :func:`pick_peaks` — peaks of the mode indicator ``Σ_channels |H_d|²``
  with the receptance ``H_d = H / (−ω²)`` (accelerance peaks sit slightly
  above the natural frequency), parabolic refinement on the log indicator.
- :func:`half_power_damping` — ``ζ = |ω₂ − ω₁| / (2ωₙ)`` at ``A/√2`` of the
  amplitude (seed eq. 2–3), i.e. half of the power indicator.
- :func:`quadrature_shapes` — Im(accelerance) at the peak (seed §2.3).

Spectra come from aligned, decimated records zero-padded to ``df_hz``; the
force is windowed (zero after ``force_window_s``) to keep its noise out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np

from ringfit.errors import InputError
from ringfit.io.records import MeasuredFRF, Records
from ringfit.targets.decimation import decimate, decimation_factor
from ringfit.targets.preprocessing import SKIP_AFTER_IMPACT_S, align_on_impact, check_angles, check_band


@dataclass
class FRFEstimate:
    """H1 accelerance [m/s²/N] and coherence per sensor angle and axis.

    ``freq_hz`` (F,), ``h1`` and ``coherence`` (angles, axes, F; NaN where a
    measured FRF came without coherence), ``angle_deg`` (angles,), ``axes``,
    ``kept`` (records,) bool: impacts used; ``notes`` one-line findings of the
    pre-processing (offsets, channels left out); ``credible`` False when
    noise dominates the records; ``measured`` True for FRFs read from a file; ``lines_hz`` the mains lines
    notched in the records and ``duration_s`` their length (:func:`~ringfit.targets.faults.repair_records`).
    """

    freq_hz: np.ndarray
    h1: np.ndarray
    coherence: np.ndarray
    angle_deg: np.ndarray
    axes: tuple
    kept: np.ndarray
    notes: list = field(default_factory=list)
    credible: bool = True
    measured: bool = False
    lines_hz: list = field(default_factory=list)
    duration_s: float = float("inf")


def h1_coherence(force_spec: np.ndarray, acc_spec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """H1 and coherence Γ (seed eq. 1) from the spectra of repeated impacts.

    **Arguments:** ``force_spec`` (impacts, F), ``acc_spec`` (impacts, axes, F), complex.

    **Returns:** ``(h1, gamma)``, each (axes, F).
    """
    sff = np.mean(np.abs(force_spec) ** 2, axis=0)
    sfx = np.mean(np.conj(force_spec)[:, None, :] * acc_spec, axis=0)
    sxx = np.mean(np.abs(acc_spec) ** 2, axis=0)
    h1 = sfx / sff
    gamma = np.sqrt(np.abs(sfx) ** 2 / np.maximum(sxx * sff, np.finfo(float).tiny))
    return h1, gamma


def reject_impacts(force_spec: np.ndarray, acc_spec: np.ndarray, band: np.ndarray, min_coherence: float = 0.9) -> np.ndarray:
    """Bool mask of the impacts kept (see module docstring). ``band``: bool (F,) frequencies judged."""
    keep = np.ones(force_spec.shape[0], bool)

    def score(mask):
        return float(np.mean(h1_coherence(force_spec[mask], acc_spec[mask])[1][:, band]))

    while keep.sum() > 2 and score(keep) < min_coherence:
        trials = []
        for i in np.flatnonzero(keep):
            m = keep.copy()
            m[i] = False
            trials.append((score(m), i))
        best, i = max(trials)
        if best <= score(keep):
            break
        keep[i] = False
    return keep


def frf_estimate(
    records: Records,
    *,
    f_max_hz: float = 400.0,
    df_hz: float = 0.05,
    threshold: float = 0.1,
    delay_s: float = 0.0,
    pre_s: float = 0.005,
    force_window_s: float = 0.02,
    min_coherence: float = 0.9,
    f_range: tuple[float, float] = (20.0, 400.0),
) -> FRFEstimate:
    """H1 and coherence per sensor angle, with impact rejection (records must carry force).

    Offsets are removed and dead axes left out first
    (:func:`~ringfit.targets.quality.clean_records`), rig faults found and
    mended or marked (:func:`~ringfit.targets.faults.repair_records`: a record
    with a dead, clipped, sign-flipped or spiky channel is left out); a record with a junk,
    flat or out-of-scale channel (:func:`~ringfit.targets.quality.screen_channels`)
    is left out as a whole, and every such finding is a note of the estimate.
    """
    from ringfit.targets.quality import channel_labels, clean_records, screen_channels

    if records.force is None:
        raise InputError("FRF needs a force channel; use SSI for records without force", source=records.source)
    from ringfit.targets.faults import repair_records, repair_timing

    check_band(records, f_max_hz)
    check_angles(records.sensor_angle_deg, records.source)
    records, notes, timing_ok = repair_timing(records)
    records, cleaned = clean_records(records, threshold)
    notes += cleaned
    records, use, found, lines = repair_records(records, threshold=threshold, f_max_hz=f_max_hz,
                                                skip_s=pre_s + SKIP_AFTER_IMPACT_S)
    notes += found
    acc, force = align_on_impact(records, threshold=threshold, delay_s=delay_s, pre_s=pre_s)
    q = decimation_factor(records.fs_hz, f_max_hz)
    acc, fs = decimate(acc, records.fs_hz, q)
    force, _ = decimate(force, records.fs_hz, q)
    pre = int(round(pre_s * fs))
    if acc.shape[-1] - pre < 64:
        raise InputError(f"only {acc.shape[-1] - pre} samples at {fs:g} Hz after the impact; expected at least 64 "
                         "(records too short?)", source=records.source)
    r, a, _ = acc.shape
    fine = use.all(axis=1)  # records without a fault found by repair_records
    if not fine.any():
        raise InputError("every record has a faulty channel; nothing left for the FRF: " + "; ".join(found),
                         source=records.source)
    try:
        screen = screen_channels(acc[fine, :, pre:].reshape(int(fine.sum()) * a, -1),
                                 channel_labels(records.sensor_angle_deg[fine], records.axes))
    except InputError as exc:
        raise InputError(str(exc), source=records.source) from None
    notes += screen.notes
    usable = fine.copy()
    usable[fine] = screen.keep.reshape(-1, a).all(axis=1)
    if not usable.any():
        raise InputError("every record has a bad channel; nothing left for the FRF", source=records.source)
    if not usable.all():
        notes.append(f"{int((~usable).sum())} record(s) with a bad channel left out of the FRF")
    force = force * (np.arange(force.shape[-1]) / fs <= pre_s + force_window_s)
    nfft = max(int(np.ceil(fs / df_hz)), acc.shape[-1])
    f = np.fft.rfftfreq(nfft, 1 / fs)
    fspec = np.fft.rfft(force, nfft, axis=-1)
    aspec = np.fft.rfft(acc, nfft, axis=-1) * np.exp(2j * np.pi * f * pre_s)  # time origin at the impact
    fspec = fspec * np.exp(2j * np.pi * f * pre_s)
    band = (f >= f_range[0]) & (f <= f_range[1])
    angles, inverse = np.unique(np.round(records.sensor_angle_deg, 9), return_inverse=True)
    kept = np.ones(records.n_records, bool)
    h1 = np.zeros((angles.size, len(records.axes), f.size), complex)
    coh = np.zeros_like(h1, dtype=float)
    kept &= usable
    for g in range(angles.size):
        idx = np.flatnonzero((inverse == g) & usable)
        if idx.size == 0:
            continue
        keep = reject_impacts(fspec[idx], aspec[idx], band, min_coherence) if idx.size > 2 else np.ones(idx.size, bool)
        kept[idx[~keep]] = False
        h1[g], coh[g] = h1_coherence(fspec[idx[keep]], aspec[idx[keep]])
    have = np.isin(np.arange(angles.size), inverse[usable])
    return FRFEstimate(f, h1[have], coh[have], angles[have], tuple(records.axes), kept, notes,
                       screen.credible and timing_ok,
                       lines_hz=lines, duration_s=records.n_samples / records.fs_hz)


def frf_from_measured(m: MeasuredFRF, f_range: tuple[float, float] = (20.0, 400.0)) -> FRFEstimate:
    """An :class:`FRFEstimate` from FRFs measured by other software (e.g. UFF58 function type 4).

    FRFs of the same sensor angle are averaged (each with the same weight;
    a note says how many were); the band must lie inside the measured lines.
    """
    f = m.freq_hz
    check_angles(m.sensor_angle_deg, m.source)
    if f_range[1] > f[-1] or f_range[0] < f[0]:
        raise InputError(f"band {f_range[0]:g}–{f_range[1]:g} Hz reaches beyond the measured lines "
                         f"{f[0]:g}–{f[-1]:g} Hz", source=m.source)
    if np.count_nonzero((f >= f_range[0]) & (f <= f_range[1])) < 8:
        raise InputError(f"fewer than 8 measured lines in {f_range[0]:g}–{f_range[1]:g} Hz (line spacing "
                         f"{f[1] - f[0]:g} Hz)", source=m.source)
    angles, inverse = np.unique(np.round(m.sensor_angle_deg, 9), return_inverse=True)
    h1 = np.stack([m.frf[inverse == g].mean(axis=0) for g in range(angles.size)])
    if m.coherence is not None:
        coh = np.stack([m.coherence[inverse == g].mean(axis=0) for g in range(angles.size)])
    else:
        coh = np.full(h1.shape, np.nan)
    notes = []
    if angles.size < m.n_records:
        notes.append(f"{m.n_records} measured FRFs at {angles.size} sensor angles: FRFs of one angle averaged")
    return FRFEstimate(f, h1, coh, angles, tuple(m.axes), np.ones(m.n_records, bool), notes, True, measured=True)


def mode_indicator(frf: FRFEstimate) -> np.ndarray:
    """``Σ_channels |H / (−ω²)|²`` (F,): receptance power summed over angles and axes."""
    w2 = (2 * np.pi * frf.freq_hz) ** 2
    hd = frf.h1 / np.where(w2 > 0, -w2, -np.inf)
    return np.sum(np.abs(hd) ** 2, axis=(0, 1))


def pick_peaks(freq_hz: np.ndarray, indicator: np.ndarray, f_range=(20.0, 400.0), prominence_db: float = 1.0) -> np.ndarray:
    """Refined peak frequencies [Hz] of the indicator in ``f_range`` (parabolic fit on the log)."""
    from scipy.signal import find_peaks

    band = np.flatnonzero((freq_hz >= f_range[0]) & (freq_hz <= f_range[1]))
    logi = 10 * np.log10(np.maximum(indicator, np.finfo(float).tiny))
    k, _ = find_peaks(logi[band], prominence=prominence_db)
    k = band[k]
    df = freq_hz[1] - freq_hz[0]
    a, b, c = logi[k - 1], logi[k], logi[k + 1]
    den = a - 2 * b + c
    return freq_hz[k] + np.where(den != 0, 0.5 * (a - c) / np.where(den != 0, den, 1), 0) * df


def half_power_damping(freq_hz: np.ndarray, power: np.ndarray, f_peak: float) -> float:
    """ζ = (f₂ − f₁) / (2 f_n) from the half-power points of a power indicator (seed eq. 2–3)."""
    k = int(np.argmin(np.abs(freq_hz - f_peak)))
    half = power[k] / 2
    lo = k
    while lo > 0 and power[lo] > half:
        lo -= 1
    hi = k
    while hi < power.size - 1 and power[hi] > half:
        hi += 1
    if power[lo] > half or power[hi] > half:
        return float("nan")
    f1 = np.interp(half, [power[lo], power[lo + 1]], [freq_hz[lo], freq_hz[lo + 1]])
    f2 = np.interp(half, [power[hi], power[hi - 1]], [freq_hz[hi], freq_hz[hi - 1]])
    return float((f2 - f1) / (2 * f_peak))


def undamped_frequency(f_peak: float, zeta: float) -> float:
    """Natural frequency f_n [Hz] of a receptance-power peak at ``f_peak``: ``f_peak / √(1 − 2ζ²)`` (docs/physics.md §9).

    ``|H_d(ω)|² = 1/((ω_n² − ω²)² + (2ζω_nω)²)`` peaks at ``ω_n √(1 − 2ζ²)``:
    the peak sits ζ² below f_n (0.06 % at ζ = 2.5 %, 4 % at 20 %). ζ unknown
    (NaN) or ≥ 1/√2 (no peak): ``f_peak`` unchanged.
    """
    if not (np.isfinite(zeta) and 0 <= zeta < np.sqrt(0.5)):
        return float(f_peak)
    return float(f_peak / np.sqrt(1.0 - 2.0 * zeta**2))


#: Share of ζ²·f_n taken as the peak-picking part of ``freq_std_hz`` (see :func:`peak_frequency_std`).
PEAK_MODEL_SHARE = 0.5


def peak_frequency_std(local_peaks_hz: np.ndarray, fn_hz: float, zeta: float) -> float:
    """``freq_std_hz`` of a peak-picked mode [Hz]: the spread of the angles' peaks ⊕ a peak-picking part.

    ``σ² = (std(local)/√angles)² + (PEAK_MODEL_SHARE · ζ² · f_n)²``: the first
    term is the scatter of the peak of each sensor angle's receptance power
    within ±1 % of the mode; the second is what the angles share and their
    scatter cannot show: the neighbours' tails and the half-power ζ used in
    :func:`undamped_frequency` move a peak by a share of ζ² f_n (on synthetic
    records at ζ = 2.5–10 % the corrected peaks sat within 0.5 ζ² f_n of the
    truth where the angles' scatter was ten times smaller). ζ unknown: the
    first term alone.
    """
    local = np.asarray(local_peaks_hz, dtype=np.float64)
    spread = float(np.std(local, ddof=1) / np.sqrt(local.size)) if local.size > 1 else 0.0
    model = PEAK_MODEL_SHARE * zeta**2 * fn_hz if np.isfinite(zeta) else 0.0
    return float(np.hypot(spread, model))


def quadrature_shapes(frf: FRFEstimate, f_peak: float) -> np.ndarray:
    """Im(accelerance) at the bin nearest ``f_peak`` (seed §2.3), shape (angles·axes,) in channel order."""
    k = int(np.argmin(np.abs(frf.freq_hz - f_peak)))
    return np.imag(frf.h1[:, :, k]).reshape(-1)


def harmonic_indicators(frf: FRFEstimate, n_max: int | None = None) -> np.ndarray:
    """Receptance power of each circumferential harmonic, shape (n_max+1, F).

    ``I_n(f) = Σ_axes |c_n(f)|² + |c_{−n}(f)|²`` with c the least-squares
    harmonic coefficients of ``H(θ, f)/(−ω²)`` around the tyre (see
    :mod:`ringfit.targets.shapes`). Modes of different n are orthogonal around
    a ring, so each I_n holds only the modes of index n: neighbours no longer
    overlap (peaks and half-power widths are cleaner than on the summed
    indicator) and n comes with the peak.
    """
    from ringfit.targets.shapes import max_harmonic

    theta = np.deg2rad(frf.angle_deg)
    m_max = max_harmonic(theta) if n_max is None else min(n_max, max_harmonic(theta))
    m = np.arange(-m_max, m_max + 1)
    pinv = np.linalg.pinv(np.exp(1j * theta[:, None] * m[None, :]))  # (2M+1, angles)
    w2 = (2 * np.pi * frf.freq_hz) ** 2
    hd = frf.h1 / np.where(w2 > 0, -w2, -np.inf)
    c = np.einsum("ma,axf->mxf", pinv, hd)
    p = np.sum(np.abs(c) ** 2, axis=1)  # (2M+1, F)
    out = p[m_max:].copy()
    out[1:] += p[m_max - 1::-1][:m_max]
    return out


#: A peak is resolved when the line spacing is at most this share of its frequency (the ±1 % window of the
#: per-angle peaks holds a line, and a half-power width of ζ = 0.5 % spans a line).
RESOLVE_SHARE = 0.01
#: The mode indicators of :func:`frf_modes`: ``"harmonic"`` (each circumferential harmonic's power,
#: :func:`harmonic_indicators`) or ``"sum"`` (the summed receptance power, :func:`mode_indicator`).
Indicator = Literal["harmonic", "sum"]


def frf_modes(records: Records | MeasuredFRF, *, f_range: tuple[float, float] = (20.0, 400.0), delay_s: float = 0.0,
              threshold: float = 0.1, min_coherence: float = 0.9, prominence_db: float = 3.0,
              indicator: Indicator = "harmonic", cavity_hz: float | None = None):
    """Peak picking on H1 (seed §2.2–2.3) → :class:`~ringfit.targets.identify.ModeIdentification`.

    ``indicator="sum"`` picks peaks on the summed receptance power (the
    source's way, one indicator for all channels); ``"harmonic"`` (default)
    picks them on each circumferential harmonic's power
    (:func:`harmonic_indicators`), which separates close modes of different n
    (e.g. the cavity mode beside n = 6) and gives cleaner half-power widths.
    A harmonic's peak counts only where that harmonic dominates the others
    (this drops the noise ripple of the weak harmonics); a peak found in
    several harmonics is kept once, in its strongest one.

    ``records`` may be time records (H1 is estimated here) or FRFs measured
    by other software (:class:`~ringfit.io.records.MeasuredFRF`, used as they are).
    ``cavity_hz``: the cavity frequency of eq. 22 (see :func:`~ringfit.targets.identify.classify_rows`).
    """
    from ringfit.targets.clustering import PhysicalMode
    from ringfit.targets.identify import ModeIdentification, mode_table, note_quality

    if isinstance(records, MeasuredFRF):
        frf = frf_from_measured(records, f_range)
    else:
        frf = frf_estimate(records, f_max_hz=f_range[1], delay_s=delay_s, threshold=threshold,
                           min_coherence=min_coherence, f_range=f_range)
    f = frf.freq_hz
    if indicator == "sum":
        curves = mode_indicator(frf)[None]
    elif indicator == "harmonic":
        curves = harmonic_indicators(frf)
    else:
        raise ValueError(f"unknown indicator {indicator!r}; expected {' or '.join(map(repr, get_args(Indicator)))}")
    found = []  # (freq, curve index, strength)
    for i, curve in enumerate(curves):
        for fp in pick_peaks(f, curve, f_range, prominence_db):
            k = int(np.argmin(np.abs(f - fp)))
            if int(np.argmax(curves[:, k])) == i:  # the harmonic must dominate at its own peak
                found.append((float(fp), i, float(curve[k])))
    found.sort(key=lambda x: -x[2])
    peaks = []
    for fp, i, strength in found:  # strongest first; drop weaker echoes of a peak in other harmonics
        if all(abs(fp - q[0]) > 0.005 * fp for q in peaks):
            peaks.append((fp, i))
    peaks.sort()
    df = float(f[1] - f[0])
    coarse = [fp for fp, _ in peaks if df > RESOLVE_SHARE * fp]
    if frf.measured and coarse:
        # a peak narrower than the line spacing: neither its frequency (to 1 %) nor its half-power width is resolved
        raise InputError(f"--band {f_range[0]:g}:{f_range[1]:g}: the measured lines are {df:g} Hz apart, coarser than "
                         f"{RESOLVE_SHARE:.0%} of the peak at {coarse[0]:.4g} Hz; expected a band above "
                         f"{df / RESOLVE_SHARE:g} Hz for these lines (or FRFs with finer lines)", source=records.source)
    angle = np.repeat(np.deg2rad(frf.angle_deg), len(frf.axes))
    axis = np.tile(np.array(frf.axes, dtype=object), frf.angle_deg.size)
    w2 = (2 * np.pi * f) ** 2
    per_angle = np.sum(np.abs(frf.h1 / np.where(w2 > 0, -w2, -np.inf)) ** 2, axis=1)
    modes = []
    for fp, i in peaks:
        # ±1 % of the peak, and never narrower than the nearest line and its neighbours (coarse lines at low f)
        near = int(np.argmin(np.abs(f - fp)))
        win = (np.abs(f - fp) <= 0.01 * fp) | (np.abs(np.arange(f.size) - near) <= 1)
        local = f[win][np.argmax(per_angle[:, win], axis=1)]
        shape = quadrature_shapes(frf, fp)
        nrm = np.linalg.norm(shape)
        shape = shape / nrm if nrm > 0 else shape
        zeta = half_power_damping(f, curves[i], fp)
        fn = undamped_frequency(fp, zeta)
        modes.append(PhysicalMode(
            freq_hz=fn, freq_std_hz=peak_frequency_std(local, fn, zeta),
            damping=zeta, damping_std=float("nan"), split_hz=0.0,
            basis=shape[:, None].astype(complex), shape=shape.astype(complex), pole_index=np.zeros(0, int), n_orders=0,
        ))
    table, modes = mode_table(modes, angle, axis, f"frf-peak-picking-{indicator}", cavity_hz=cavity_hz,
                              lines_hz=frf.lines_hz, duration_s=frf.duration_s, notes=frf.notes)
    limits = []
    if not (table.kind == "acoustic").any():
        limits.append("no acoustic (cavity) row: peak picking finds an acoustic mode only where its peak stands out "
                      "from the ring modes in a harmonic's indicator (the cavity's n = 1 pattern sits among the "
                      "higher ring modes); `ringfit ssi` separates it by damping and shape")
    if frf.measured:
        table.condition["method"] += " (measured FRFs)"
    note_quality(table, frf.notes, frf.credible, limits)
    return ModeIdentification(table, modes, angle, axis, float(2 * f[-1]), frf=frf,
                              info={"kept_impacts": int(frf.kept.sum()), "impacts": int(frf.kept.size),
                                    "indicator": indicator, "notes": list(frf.notes), "credible": frf.credible,
                                    "limits": limits})
