"""From records to a mode table: the SSI chain of the source study, end to end.

``records → align (force threshold and delay, or group velocity) → decimate
→ drop the first 0.0127 s → average repeated impacts per angle → SSI-cov
→ stabilization → clustering → n, travelling measure, acoustic flag →
σ by jackknife → ModeTable`` (docs/formats.md §2; sidecar state ``free``,
frame ``fixed``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ringfit.errors import InputError
from ringfit.io.modes import ModeTable
from ringfit.io.records import Records
from ringfit.targets.clustering import PhysicalMode, cluster_modes
from ringfit.targets.decimation import decimate, decimation_factor
from ringfit.targets.preprocessing import (
    SKIP_AFTER_IMPACT_S,
    align_on_impact,
    check_angles,
    check_band,
    drop_after_impact,
    sync_by_group_velocity,
)
from ringfit.targets.shapes import acoustic_candidates, mode_number, travelling_measure
from ringfit.targets.ssi import PoleSet, default_workers, ssi_cov_factors
from ringfit.targets.stabilization import Stability, stabilization_diagram
from ringfit.targets.uncertainty import angle_groups, jackknife_modes


@dataclass
class ModeIdentification:
    """Everything an identification produced, for plots and reports.

    ``table`` (the mode table), ``modes`` (:class:`PhysicalMode` list, same
    order as the table rows), ``angle_rad``/``axis`` per channel, ``fs_hz``
    after decimation, and for SSI ``poles`` and ``stability``; for FRF ``frf``.
    """

    table: ModeTable
    modes: list
    angle_rad: np.ndarray
    axis: np.ndarray
    fs_hz: float
    poles: PoleSet | None = None
    stability: Stability | None = None
    frf: object | None = None
    info: dict = field(default_factory=dict)


def average_by_angle(acc: np.ndarray, angle_deg: np.ndarray, use: np.ndarray | None = None):
    """Mean of the aligned records taken at the same sensor angle: (records, axes, samples) -> (angles, axes, samples).

    ``use`` (records, axes) bool: the channels of each record that count (default all); then the result is
    ``(mean, angles, have)`` with ``have`` (angles, axes) True where at least one record counted.
    """
    angles, inverse = np.unique(np.round(np.asarray(angle_deg, dtype=np.float64), 9), return_inverse=True)
    w = np.ones(acc.shape[:2]) if use is None else np.asarray(use, dtype=np.float64)
    out = np.zeros((angles.size,) + acc.shape[1:])
    np.add.at(out, inverse, acc * w[..., None])
    count = np.zeros((angles.size, acc.shape[1]))
    np.add.at(count, inverse, w)
    mean = out / np.maximum(count, 1)[..., None]
    return (mean, angles) if use is None else (mean, angles, count > 0)


@dataclass
class Decays:
    """Aligned, decimated free decays of the records, screened for bad channels.

    ``y`` (channels, samples) [m/s²], ``angle_rad`` and ``axis`` per channel,
    ``fs_hz`` after decimation, ``screen`` the
    :class:`~ringfit.targets.quality.ChannelScreen` of the channels before
    the bad ones were left out (None when not screened), ``notes`` one-line
    findings of the pre-processing (offsets, channels left out, credibility), ``lines_hz`` the mains lines
    notched (:func:`~ringfit.targets.faults.repair_records`), ``duration_s`` the records' length, ``timing_ok``
    False when a stalled stream could not be mended (:func:`~ringfit.targets.faults.repair_timing`).
    """

    y: np.ndarray
    angle_rad: np.ndarray
    axis: np.ndarray
    fs_hz: float
    screen: object = None
    notes: list = field(default_factory=list)
    lines_hz: list = field(default_factory=list)
    duration_s: float = float("inf")
    timing_ok: bool = True

    @property
    def credible(self) -> bool:
        return self.timing_ok and (self.screen is None or bool(self.screen.credible))


#: Fewest free-decay samples (after alignment, decimation and the skip) an SSI run accepts.
MIN_DECAY_SAMPLES = 64


def free_decays(
    records: Records,
    *,
    f_max_hz: float = 400.0,
    decimate_to: float | None = None,
    skip_s: float = SKIP_AFTER_IMPACT_S,
    threshold: float = 0.1,
    delay_s: float = 0.0,
    radius_m: float | None = None,
    average: bool = True,
    screen: bool = True,
) -> Decays:
    """Offsets removed, aligned, averaged per angle, decimated free decays; bad channels left out.

    **Arguments:** ``f_max_hz`` sets the default decimation
    (:func:`decimation_factor`), ``decimate_to`` [Hz] an explicit target rate;
    ``radius_m`` is needed when the records carry no force (group-velocity
    sync); ``screen`` runs :func:`~ringfit.targets.quality.screen_channels`.

    **Raises** :class:`InputError` when the band lies above the records'
    Nyquist frequency, the decays are too short, or no channel is usable.
    """
    from ringfit.targets.quality import channel_labels, clean_records, screen_channels

    from ringfit.targets.faults import repair_records, repair_timing

    check_band(records, f_max_hz)
    check_angles(records.sensor_angle_deg, records.source)
    records, notes, timing_ok = repair_timing(records)
    records, cleaned = clean_records(records, threshold)
    notes += cleaned
    records, use, found, lines = repair_records(records, threshold=threshold, f_max_hz=f_max_hz, skip_s=skip_s,
                                                used_from_s=skip_s + delay_s)
    notes += found
    if records.force is not None:
        acc, _ = align_on_impact(records, threshold=threshold, delay_s=delay_s)
    else:
        if radius_m is None:
            raise InputError("records without a force channel need the tyre radius for group-velocity sync", source=records.source)
        acc, _ = sync_by_group_velocity(records, radius_m)
    angle_deg = records.sensor_angle_deg
    if average:
        acc, angle_deg, use = average_by_angle(acc, angle_deg, use)
    q = decimation_factor(records.fs_hz, f_max_hz) if decimate_to is None else max(1, int(round(records.fs_hz / decimate_to)))
    acc, fs = decimate(acc, records.fs_hz, q)
    acc = drop_after_impact(acc, fs, skip_s)
    r, a, s = acc.shape
    if s < MIN_DECAY_SAMPLES:
        raise InputError(f"only {s} samples of free decay at {fs:g} Hz after alignment, decimation and the skip; "
                         f"expected at least {MIN_DECAY_SAMPLES} (records too short?)", source=records.source)
    y = acc.reshape(r * a, s)
    angle = np.repeat(np.deg2rad(angle_deg), a)
    axis = np.tile(np.array(records.axes, dtype=object), r)
    labels = channel_labels(angle_deg, records.axes)
    have = np.asarray(use, bool).reshape(-1)  # channels with a usable record (repair_records)
    if not have.any():
        raise InputError("no usable acceleration channel: " + "; ".join(found), source=records.source)
    y, angle, axis, labels = y[have], angle[have], axis[have], [x for x, h in zip(labels, have) if h]
    found = None
    if screen:
        try:
            found = screen_channels(y, labels)
        except InputError as exc:
            raise InputError(str(exc), source=records.source) from None
        notes += found.notes
        y, angle, axis = y[found.keep], angle[found.keep], axis[found.keep]
    return Decays(y, angle, axis, fs, found, notes, lines, records.n_samples / records.fs_hz, timing_ok)


def prepare_decays(records: Records, **kwargs) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """:func:`free_decays` without the channel screen, as ``(y, angle_rad, axis, fs_hz)``."""
    d = free_decays(records, screen=False, **kwargs)
    return d.y, d.angle_rad, d.axis, d.fs_hz


#: Relative tolerance around the cavity frequency of eq. 22 (docs/physics.md §3.6) within which a non-ring-like
#: row may be the cavity: the speed of sound moves ±3.5 % over 0–40 °C and the effective cavity length of a
#: tyre differs from the geometry's by a few percent (the thesis measured 227.0 Hz against 218.75 Hz, +3.8 %).
CAVITY_TOL = 0.08
#: Least share of the shape's power in harmonic n = 1 for a cavity row (the tread sensor sees the cavity's
#: pressure drive the ring's rigid n = 1 motion).
CAVITY_MIN_CONFIDENCE = 0.5


#: An acoustic row is lighter damped than the rubber: its damping below this share of the ring-like rows' median
#: (the air's losses are the walls'; the example's cavity 0.7 % against 2.5 %). A ring mode whose shape the hum
#: left reading n = 1 near the cavity frequency keeps the ring's damping (2.4 % against 2.5 %).
AIR_DAMPING_SHARE = 0.75


def classify_rows(n: np.ndarray, confidence: np.ndarray, freq_hz: np.ndarray, not_ring: np.ndarray,
                  cavity_hz: float | None, tol: float = CAVITY_TOL, lines_hz=(), duration_s: float = np.inf,
                  damping: np.ndarray | None = None, ring_damping: float = np.nan
                  ) -> tuple[np.ndarray, np.ndarray]:
    """``structural``, ``acoustic`` or ``unclassified`` for each row, and the reason of each unclassified one.

    A row that is ring-like (``not_ring`` False) is ``structural``. A row that is not is ``acoustic`` only with
    evidence: its frequency within ``tol`` of the cavity frequency ``cavity_hz`` (eq. 22, docs/physics.md §3.6)
    AND an n = 1-like shape (dominant harmonic 1 holding at least :data:`CAVITY_MIN_CONFIDENCE` of the power)
    AND, given ``damping`` (rows,) and the ring-like rows' median ``ring_damping``, lighter damped than the
    rubber (below :data:`AIR_DAMPING_SHARE` of it); otherwise it is ``unclassified`` and the reason says which
    evidence is missing. Any row on a mains line
    that was notched (``lines_hz``, :func:`~ringfit.targets.faults.on_notched_line`) is ``unclassified``.

    **Returns:** ``(kind, reason)``, object arrays (rows,); reason ``""`` for structural rows only (an
    ``acoustic`` row says what made it the cavity).
    """
    kind = np.where(not_ring, "unclassified", "structural").astype(object)
    reason = np.full(len(kind), "", dtype=object)
    from ringfit.targets.faults import on_notched_line

    for i in range(len(kind)):
        line = on_notched_line(float(freq_hz[i]), lines_hz, duration_s)
        if line is not None:
            kind[i] = "unclassified"
            reason[i] = (f"on the mains line at {line:.2f} Hz that was notched: what is left of the hum, "
                         "not shown to be a mode")
    for i in np.flatnonzero(not_ring & (reason == "")):
        shape = (f"dominant harmonic n = {int(n[i])} with {100 * confidence[i]:.0f} % of the shape's power"
                 if confidence[i] >= CAVITY_MIN_CONFIDENCE else
                 f"no dominant harmonic (n = {int(n[i])} holds only {100 * confidence[i]:.0f} % of the power)")
        why = ["not ring-like (" + (shape if confidence[i] < CAVITY_MIN_CONFIDENCE else
                                    f"n = {int(n[i])} out of the ring's order of frequencies") + ")"]
        if cavity_hz is None or not np.isfinite(cavity_hz):
            why.append("no cavity frequency given to compare with")
        else:
            off = freq_hz[i] / cavity_hz - 1
            near = abs(off) <= tol
            one = int(n[i]) == 1 and confidence[i] >= CAVITY_MIN_CONFIDENCE
            light = (damping is None or not np.isfinite(ring_damping) or ring_damping <= 0
                     or damping[i] < AIR_DAMPING_SHARE * ring_damping)
            if near and one and not light:
                why.append(f"damped like the ring ({100 * damping[i]:.2f} % against the ring modes' median "
                           f"{100 * ring_damping:.2f} %; the air is lighter damped than "
                           f"{100 * AIR_DAMPING_SHARE:g} % of it): not the cavity")
            if near and one and light:
                kind[i] = "acoustic"
                reason[i] = (f"the cavity: not ring-like, {100 * off:+.1f} % from eq. 22's {cavity_hz:.2f} Hz "
                             f"(tolerance ±{100 * tol:g} %) with the cavity's n = 1 pattern ({shape})"
                             + (f", lighter damped than the ring ({100 * damping[i]:.2f} % against "
                                f"{100 * ring_damping:.2f} %)" if damping is not None and np.isfinite(ring_damping)
                                and ring_damping > 0 else ""))
                continue
            if not near:
                why.append(f"not the cavity: {100 * off:+.0f} % from eq. 22's {cavity_hz:.2f} Hz "
                           f"(tolerance ±{100 * tol:g} %)")
            if not one:
                why.append(f"not the cavity's n = 1 pattern ({shape})")
        reason[i] = "; ".join(why)
    return kind, reason


#: A row that is not ring-like within this relative distance of a structural row is the same mode found twice
#: (its shape read through what the notch or the noise left, or a half of the double pole clustered apart): the
#: split of a ring mode's double pole is well under it, the cavity and its nearest ring mode lie further apart.
TWICE_TOL = 0.005
#: ... or within 3 σ of the two rows' frequencies (their spread over the model orders), up to this: the distance
#: within which two rows of the same n are the two halves of one double pole
#: (:func:`~ringfit.targets.clustering.merge_pairs`).
TWICE_CAP = 0.01


def found_twice(freq_hz: np.ndarray, kind: np.ndarray, tol: float = TWICE_TOL,
                skip: np.ndarray | None = None, freq_std_hz: np.ndarray | None = None,
                cap: float = TWICE_CAP) -> list[tuple[int, int]]:
    """``[(row, structural_row)]``: each row that is not ``structural`` within ``tol`` (relative) of a structural
    row — or within 3 σ of the two (``freq_std_hz``), up to ``cap`` — with the nearest such row; rows where
    ``skip`` is True (on a notched mains line: what the hum left, not the mode) are not paired."""
    freq_hz = np.asarray(freq_hz, dtype=np.float64)
    kind = np.asarray(kind, dtype=object)
    std = np.zeros_like(freq_hz) if freq_std_hz is None else np.nan_to_num(np.asarray(freq_std_hz, np.float64))
    st = np.flatnonzero(kind == "structural")
    out = []
    if not st.size:
        return out
    other = kind != "structural"
    if skip is not None:
        other &= ~np.asarray(skip, dtype=bool)
    for i in np.flatnonzero(other):
        off = np.abs(freq_hz[st] / freq_hz[i] - 1)
        allowed = np.minimum(cap, np.maximum(tol, 3 * np.hypot(std[i], std[st]) / freq_hz[i]))
        j = int(np.argmin(off / allowed))
        if off[j] <= allowed[j]:
            out.append((int(i), int(st[j])))
    return out


def mode_table(modes: Sequence[PhysicalMode], angle_rad: np.ndarray, axis: np.ndarray, method: str,
               *, min_confidence: float = 0.5, poles: PoleSet | None = None,
               spurious_damping_factor: float = 1.5, cavity_hz: float | None = None, lines_hz=(),
               duration_s: float = np.inf, notes: list | None = None) -> tuple[ModeTable, list]:
    """A :class:`ModeTable` (docs/formats.md §2) from physical modes: n from the shapes, kind, extras.

    With ``poles`` (SSI), modes with the same n within 1 % are first merged
    as the two halves of a double pole (:func:`~ringfit.targets.clustering.merge_pairs`).
    Modes that are not ring-like (:func:`~ringfit.targets.shapes.acoustic_candidates`)
    are kept when they are lighter damped than ``spurious_damping_factor`` ×
    the median structural damping (air modes are lighter damped than the
    rubber, seed §5.1); the others are dropped as mathematical (spurious)
    modes. A kept one is ``acoustic`` only with evidence, else
    ``unclassified`` with the reason (:func:`classify_rows`; ``cavity_hz``
    the cavity frequency of eq. 22 for the tyre, None: nothing is called acoustic; ``lines_hz`` the notched
    mains lines and ``duration_s`` the records' length). Before any row is classified, a row that is not
    ring-like within :data:`TWICE_TOL` (or 3 σ, up to :data:`TWICE_CAP`) of a ring-like row, and not on a
    notched mains line, is the other half of that mode's double pole whatever n its shape reads
    (:func:`found_twice`): its poles are merged into the ring-like row
    (:func:`~ringfit.targets.clustering.merge_twins`), and ``notes`` (when given) gets a line saying so.

    Extra columns: ``n_confidence``, ``split_hz``, ``travelling``, ``damping_std_pct``, ``reason``.

    **Returns:** ``(table, modes)`` with ``modes`` in table order.
    """
    from ringfit.targets.clustering import merge_pairs, merge_twins
    from ringfit.targets.faults import on_notched_line

    modes = list(modes)
    n = np.array([mode_number(m.basis, angle_rad, axis)[0] for m in modes], dtype=np.int64)
    if poles is not None:
        modes, n = merge_pairs(poles, modes, n)
    # the two halves of one double pole whose second half's shape reads another n (issue 34): one row, before
    # anything is classified (a half read as n = 1 near the cavity frequency must not become an acoustic row)
    conf = np.array([mode_number(m.basis, angle_rad, axis)[1] for m in modes])
    freq = np.array([m.freq_hz for m in modes])
    not_ring = acoustic_candidates(n, conf, freq, min_confidence)
    on_line = np.array([on_notched_line(float(f), lines_hz, duration_s) is not None for f in freq], dtype=bool)
    twice = found_twice(freq, np.where(not_ring | on_line, "other", "structural"), skip=on_line,
                        freq_std_hz=np.array([m.freq_std_hz for m in modes]))
    if twice:
        if notes is not None:
            shown = ", ".join(f"{freq[i]:.2f} Hz (not ring-like, its shape reads n = {int(n[i])}) beside the "
                              f"n = {int(n[j])} mode at {freq[j]:.2f} Hz" for i, j in twice[:4])
            notes.append(f"{len(twice)} mode(s) found twice, once as a structural mode and once as a row that is not "
                         f"ring-like within {100 * TWICE_TOL:g} % of it (or 3 σ of the two, up to "
                         f"{100 * TWICE_CAP:g} %): {shown}; merged into the structural row (one double pole)")
        modes, n = merge_twins(poles, modes, n, twice)
    conf, trav = [], []
    for m in modes:
        k, c = mode_number(m.basis, angle_rad, axis)
        conf.append(c)
        if poles is not None:  # poles of the orders that resolved the pair, else all
            idx = m.pole_index
            counts = np.bincount(poles.order[idx])
            two = idx[counts[poles.order[idx]] >= 2]
            shapes = poles.shape[two if two.size else idx]
        else:
            shapes = m.basis.T
        trav.append(float(np.mean([travelling_measure(s, angle_rad, axis, k) for s in shapes])))
    conf = np.array(conf)
    freq = np.array([m.freq_hz for m in modes])
    damping = np.array([m.damping for m in modes])
    not_ring = acoustic_candidates(n, conf, freq, min_confidence)
    ref = np.nanmedian(damping[~not_ring]) if (~not_ring).any() else np.inf
    keep = ~not_ring | ~(damping > spurious_damping_factor * ref)
    idx = np.flatnonzero(keep)
    kind, reason = classify_rows(n[idx], conf[idx], freq[idx], not_ring[idx], cavity_hz, lines_hz=lines_hz,
                                 duration_s=duration_s, damping=damping[idx], ring_damping=float(ref))
    modes = [modes[i] for i in idx]
    fmt = lambda x: f"{x:.6g}" if np.isfinite(x) else ""  # noqa: E731  (empty: unknown)
    table = ModeTable(
        freq_hz=freq[idx],
        n=np.where(kind == "structural", n[idx], -1),
        kind=kind,
        freq_std_hz=np.array([m.freq_std_hz for m in modes]),
        damping_pct=100 * damping[idx],
        extra={
            "n_confidence": np.array([fmt(c) for c in conf[idx]], dtype=object),
            "split_hz": np.array([fmt(m.split_hz) for m in modes], dtype=object),
            "travelling": np.array([fmt(trav[i]) for i in idx], dtype=object),
            "damping_std_pct": np.array([fmt(100 * m.damping_std) for m in modes], dtype=object),
            "reason": reason,
        },
        condition={"state": "free", "frame": "fixed", "method": method},
    )
    if cavity_hz is not None and np.isfinite(cavity_hz):
        table.condition["cavity_hz"] = float(cavity_hz)
    return table, modes


def ssi_modes(
    records: Records,
    *,
    orders: Sequence[int] = range(2, 161, 2),
    block_rows: int | None = 30,
    f_range: tuple[float, float] = (20.0, 400.0),
    decimate_to: float | None = None,
    skip_s: float = SKIP_AFTER_IMPACT_S,
    threshold: float = 0.1,
    delay_s: float = 0.0,
    radius_m: float | None = None,
    refs: np.ndarray | None = None,
    pair_aware: bool = True,
    min_share: float = 0.5,
    jackknife: bool = True,
    progress: bool = False,
    workers: int | None = None,
    cavity_hz: float | None = None,
) -> ModeIdentification:
    """The source's SSI chain on impact records, with pair-aware stabilization and clustering.

    **Arguments:** ``orders`` model orders; ``block_rows`` p; ``f_range`` [Hz]
    band of interest (its top sets the decimation); the pre-processing
    arguments of :func:`prepare_decays`; ``refs`` reference channels;
    ``jackknife``: σ of each mode by the jackknife over groups of sensor
    angles (:mod:`ringfit.targets.uncertainty`; ~20 % of the SSI's time);
    ``False``: σ = the spread over the model orders, said so in the method;
    ``workers`` threads for the SVD products, the order sweep and the
    jackknife's replicates (default: the usable CPUs, see
    :func:`ringfit.targets.ssi.default_workers`); ``cavity_hz`` the cavity
    frequency of eq. 22 for the tyre (a non-ring-like row is ``acoustic`` only
    near it, :func:`classify_rows`; None: such rows are ``unclassified``).

    **Returns:** :class:`ModeIdentification` (``table`` is the mode table).
    """
    d = free_decays(records, f_max_hz=f_range[1], decimate_to=decimate_to, skip_s=skip_s,
                    threshold=threshold, delay_s=delay_s, radius_m=radius_m)
    y, angle, axis, fs = d.y, d.angle_rad, d.axis, d.fs_hz
    # free decays: covariances normalised by N, not N − i (ringfit.targets.ssi.output_covariances)
    poles, factors = ssi_cov_factors(y, fs, orders=orders, block_rows=block_rows, refs=refs, unbiased=False,
                                     progress=progress, workers=workers)
    stab = stabilization_diagram(poles, pair_aware=pair_aware)
    modes = cluster_modes(poles, stab, f_range=f_range, min_share=min_share)
    table, modes = mode_table(modes, angle, axis, "ssi-cov", poles=poles, cavity_hz=cavity_hz,
                               lines_hz=d.lines_hz, duration_s=d.duration_s, notes=d.notes)
    note_quality(table, d.notes, d.credible)
    unc = jackknife_modes(factors, poles, modes, angle_groups(angle)[0] if jackknife else np.zeros(0),
                          workers=default_workers() if workers is None else workers)
    modes = apply_uncertainty(table, modes, unc)
    from ringfit.targets.quality import psd_singular_values

    return ModeIdentification(table, modes, angle, axis, fs, poles=poles, stability=stab,
                              info={"block_rows": block_rows, "channels": y.shape[0], "samples": y.shape[1],
                                    "notes": list(d.notes), "credible": d.credible,
                                    "psd_singular_values": psd_singular_values(y, fs),
                                    "uncertainty": unc, "source": records.source})


def apply_uncertainty(table: ModeTable, modes: Sequence[PhysicalMode], unc) -> list:
    """Write σ of a :class:`~ringfit.targets.uncertainty.ModeUncertainty` into the table (in place) and the modes.

    ``freq_std_hz``, the extra column ``damping_std_pct`` (empty where
    unknown) and the sidecar's ``method`` (``"ssi-cov; σ: <how>"``,
    docs/formats.md §2). **Returns** the modes with the same σ.
    """
    import dataclasses

    table.freq_std_hz = np.asarray(unc.freq_std_hz, dtype=np.float64).copy()
    table.extra["damping_std_pct"] = np.array([f"{100 * z:.6g}" if np.isfinite(z) else "" for z in unc.damping_std],
                                              dtype=object)
    table.condition["method"] = f"{table.condition.get('method', 'ssi-cov')}; σ: {unc.method}"
    return [dataclasses.replace(m, freq_std_hz=float(f), damping_std=float(z))
            for m, f, z in zip(modes, unc.freq_std_hz, unc.damping_std)]


def note_quality(table: ModeTable, notes: list[str], credible: bool, limits: list[str] = ()) -> None:
    """Put the pre-processing findings into the table's sidecar and raise them as warnings.

    Sidecar fields (docs/formats.md §2): ``preprocessing`` (one-line notes:
    offsets removed, channels left out), ``credible`` (false when noise
    dominates the records: the rows are then not to be trusted as modes) and
    ``limits`` (what the method could not see, e.g. acoustic modes for FRF
    peak picking; not warnings).
    """
    import warnings

    if notes:
        table.condition["preprocessing"] = list(notes)
    if limits:
        table.condition["limits"] = list(limits)
    table.condition["credible"] = bool(credible)
    src = table.condition.get("method", "identification")
    for note in notes:
        warnings.warn(f"{src}: {note}", RuntimeWarning, stacklevel=3)
    if not credible and len(table):
        warnings.warn(f"{src}: nothing credible found; the {len(table)} row(s) of the table are likely noise",
                      RuntimeWarning, stacklevel=3)
