"""Synthetic roving-sensor impact records from a damped ring modal model.

A free, static tyre struck radially with a hammer at θ = 0 and read by one
sensor moved around the tread band (docs/formats.md §4). Each circumferential index
n gives a DOUBLE pole (the ring is axisymmetric): two modes at
``f_n (1 ∓ split/2)`` whose symmetry axes sit at a random angle α_n (small
imperfections), so the hammer excites both and their shapes turn freely
inside the pair. ``travelling`` mixes the pair into counter-rotating waves
(0 = standing cos/sin nθ, 1 = pure e^{±inθ}).

Model (docs/physics.md §2.1 for the frequencies, taken from
:func:`ringfit.physics.natural.natural_frequencies`): inextensible ring,
radial ``w = cos n(θ−α)`` with tangential ``v = −sin n(θ−α)/n`` (w + v′ = 0);
modal mass ``πRρA(1 + 1/n²)``; sensor radial positive toward the wheel centre
(reads −w). The acceleration FRF is a pole–residue sum
``H(θ, ω) = −ω² Σ_m [R_m(θ)/(iω − λ_m) + conj(R_m(θ))/(iω − conj λ_m)]``
with ``R_m(θ) = ψ_m(θ) conj(ψ_m(0)) / (2i ω_d M_m)``; records are computed in
the frequency domain from the sampled hammer pulse (half sine), so the
records are exact samples of the periodic response (record lengths are chosen
long against the decay time).

An optional cavity mode (docs/physics.md §3.6, seed eq. 22: 343/1.568 Hz,
ζ ≈ 0.7 %) is seen by the tread sensor as the ring's rigid n = 1 motion it
drives: an n = 1 pattern far above the ring's own n = 1 frequency.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ringfit.io.records import Records


@dataclass
class SyntheticModes:
    """The known truth behind synthetic records, one row per physical mode (a pair counts once).

    **Fields** (shape ``(modes,)``): ``n`` (−1 for the cavity), ``kind``
    (``structural``/``acoustic``), ``freq_hz`` [Hz] (pair centre),
    ``damping`` [-], ``split`` [-] relative frequency split of the pair,
    ``orientation_rad`` α_n [rad], ``travelling`` [0..1], ``amplitude`` [-] relative residue scale.
    """

    n: np.ndarray
    kind: np.ndarray
    freq_hz: np.ndarray
    damping: np.ndarray
    split: np.ndarray
    orientation_rad: np.ndarray
    travelling: np.ndarray
    amplitude: np.ndarray

    def structural(self) -> np.ndarray:
        """``(modes,)`` True where the mode is a structural (ring) mode."""
        return self.kind == "structural"


def ring_modes(
    ring,
    geometry,
    n_values=range(1, 10),
    *,
    damping: float | None = None,
    split: float = 0.002,
    travelling: float = 0.0,
    cavity: bool = True,
    cavity_damping: float = 0.007,
    cavity_amplitude: float = 0.3,
    seed: int = 0,
) -> SyntheticModes:
    """Modal truth of a free ring: eq. 18 frequencies, one damping ratio, double poles, optional cavity.

    **Arguments:**

    - ``ring``, ``geometry``: :class:`~ringfit.params.RingParams`, :class:`~ringfit.params.TyreGeometry`.
    - ``n_values``: circumferential indices.
    - ``damping``: modal damping ratio [-] (default ``ring.damping_ratio``).
    - ``split``: relative frequency split of each double pole [-].
    - ``travelling``: 0 standing … 1 counter-rotating waves.
    - ``cavity``: add the first cavity mode (``cavity_frequency()``, ``cavity_damping``)
      with residue scale ``cavity_amplitude`` relative to the ring modes.
    """
    from ringfit.physics.natural import cavity_frequency, natural_frequencies

    n = np.asarray(list(n_values), dtype=np.int64)
    rng = np.random.default_rng(seed)
    f = np.asarray(natural_frequencies(ring, geometry, n.astype(np.float64)), dtype=np.float64)
    zeta = float(ring.damping_ratio) if damping is None else float(damping)
    m = n.shape[0]
    out = SyntheticModes(
        n=n,
        kind=np.full(m, "structural", dtype=object),
        freq_hz=f,
        damping=np.full(m, zeta),
        split=np.full(m, float(split)),
        orientation_rad=rng.uniform(0.1, 0.4, m) * np.pi / np.maximum(n, 1),
        travelling=np.full(m, float(travelling)),
        amplitude=np.ones(m),
    )
    if cavity:
        fc = float(cavity_frequency(1))
        for name, value in (("n", -1), ("kind", "acoustic"), ("freq_hz", fc), ("damping", cavity_damping),
                            ("split", 0.0), ("orientation_rad", 0.0), ("travelling", 0.0),
                            ("amplitude", cavity_amplitude)):
            setattr(out, name, np.append(getattr(out, name), value).astype(getattr(out, name).dtype))
    return out


def _shapes(modes: SyntheticModes, i: int, theta: np.ndarray, axes, modal_mass: float):
    """Poles (2,), complex shapes (2, len(theta), axes) of mode i's pair, and modal masses (2,).

    ``modal_mass``: M_n of the mode's n [kg] (:func:`ringfit.physics.natural.ring_modal_mass`).
    """
    n = int(modes.n[i]) if modes.n[i] >= 0 else 1
    alpha = modes.orientation_rad[i]
    beta = modes.travelling[i] * np.pi / 4
    w_a, w_b = np.cos(n * (theta - alpha)), np.sin(n * (theta - alpha))
    v_a, v_b = -np.sin(n * (theta - alpha)) / n, np.cos(n * (theta - alpha)) / n
    comp = {"radial": (-w_a, -w_b), "tangential": (v_a, v_b), "lateral": (0 * w_a, 0 * w_b)}
    phi_a = np.stack([comp[a][0] for a in axes], -1)
    phi_b = np.stack([comp[a][1] for a in axes], -1)
    psi = np.stack([np.cos(beta) * phi_a + 1j * np.sin(beta) * phi_b,
                    np.cos(beta) * phi_b - 1j * np.sin(beta) * phi_a])
    f0, zeta, split = modes.freq_hz[i], modes.damping[i], modes.split[i]
    if modes.kind[i] == "acoustic":  # one standing mode, driven along the impact axis
        psi = np.stack(_cavity_axes(axes, n, theta), -1)[None].astype(complex)
        freqs = np.array([f0])
    else:
        freqs = f0 * np.array([1 - split / 2, 1 + split / 2])
    wn = 2 * np.pi * freqs
    lam = -zeta * wn + 1j * wn * np.sqrt(1 - zeta**2)
    mass = modal_mass / modes.amplitude[i]
    return lam, psi, np.full(len(freqs), mass)


def _cavity_axes(axes, n, theta):
    # rigid n = 1 motion along the impact axis: radial -cos θ (inward +), tangential -sin θ
    return [{"radial": -np.cos(n * theta), "tangential": -np.sin(n * theta) / n, "lateral": 0 * theta}[a] for a in axes]


def impact_records(
    modes: SyntheticModes,
    angles_deg,
    *,
    ring=None,
    geometry=None,
    axes=("radial", "tangential"),
    fs_hz: float = 25600.0,
    duration_s: float = 1.0,
    impacts_per_angle: int = 1,
    pre_trigger_s: float = 0.02,
    trigger_jitter_s: float = 0.005,
    hammer_duration_s: float = 0.6e-3,
    hammer_peak_n: float = 300.0,
    hammer_spread: float = 0.2,
    sensor_delay_s: float = 0.0,
    noise: float = 0.01,
    force_noise: float = 0.005,
    with_force: bool = True,
    seed: int = 0,
) -> Records:
    """Roving-sensor hammer records of the modal model ``modes`` (docs/formats.md §4 layout).

    **Arguments:**

    - ``angles_deg``: sensor angles [deg] from the impact point, one group of
      ``impacts_per_angle`` records each.
    - ``ring``, ``geometry``: for the modal masses πRρA(1+1/n²) (default Table 9).
    - ``fs_hz``, ``duration_s``: sampling of every record.
    - ``pre_trigger_s``, ``trigger_jitter_s``: the impact happens at
      ``pre_trigger_s + U(0, trigger_jitter_s)`` in each record.
    - ``hammer_duration_s``, ``hammer_peak_n``, ``hammer_spread``: half-sine
      pulse, peak force varies by ±spread between impacts.
    - ``sensor_delay_s``: the acceleration channels lag the force by this [s]
      (the source's force/acc delay, removed in pre-processing).
    - ``noise``, ``force_noise``: white noise std relative to the rms of the
      clean acceleration (over all records) and to the peak force.
    - ``with_force``: keep the force channel (False: an unmeasured excitation).

    **Returns:** :class:`~ringfit.io.records.Records` with ``acc`` of shape
    ``(angles·impacts, axes, samples)``.
    """
    if ring is None or geometry is None:
        from ringfit.params import table9

        geometry, ring = table9()
    from ringfit.physics.natural import ring_modal_mass

    # M_n = πRρA(1 + 1/n²) of each mode's n (unassigned and acoustic rows: n = 1, as their shapes)
    masses = np.asarray(ring_modal_mass(ring, geometry, np.where(modes.n >= 0, modes.n, 1)))
    rng = np.random.default_rng(seed)
    angles = np.repeat(np.asarray(angles_deg, dtype=np.float64), int(impacts_per_angle))
    theta = np.deg2rad(angles)
    ns = int(round(duration_s * fs_hz))
    t = np.arange(ns) / fs_hz
    w = 2 * np.pi * np.fft.rfftfreq(ns, 1 / fs_hz)
    iw = 1j * w
    # accelerance per record and axis: (records, axes, freqs)
    h = np.zeros((angles.size, len(axes), w.size), dtype=complex)
    for i in range(len(modes.n)):
        lam, psi, mass = _shapes(modes, i, theta, axes, float(masses[i]))
        _, psi0, _ = _shapes(modes, i, np.zeros(1), ("radial",), float(masses[i]))
        for k in range(lam.shape[0]):
            res = psi[k] * np.conj(psi0[k][0, 0]) / (2j * lam[k].imag * mass[k])  # (records, axes); generalised force of an inward push
            h += res[..., None] / (iw - lam[k]) + np.conj(res)[..., None] / (iw - np.conj(lam[k]))
    h *= -(w**2)
    t0 = pre_trigger_s + rng.uniform(0, trigger_jitter_s, angles.size)
    peak = hammer_peak_n * (1 + hammer_spread * rng.uniform(-1, 1, angles.size))
    tau = (t[None, :] - t0[:, None]) / hammer_duration_s
    force = np.where((tau >= 0) & (tau <= 1), np.sin(np.pi * np.clip(tau, 0, 1)), 0.0) * peak[:, None]
    spec = np.fft.rfft(force, axis=-1)
    acc_spec = h * spec[:, None, :] * np.exp(-iw * sensor_delay_s)
    acc = np.fft.irfft(acc_spec, n=ns, axis=-1)
    acc += noise * np.sqrt(np.mean(acc**2)) * rng.standard_normal(acc.shape)
    force = force + force_noise * hammer_peak_n * rng.standard_normal(force.shape)
    return Records(acc=acc, axes=tuple(axes), sensor_angle_deg=angles, fs_hz=float(fs_hz),
                   force=force if with_force else None, source="<synthetic>")


#: Degradations :func:`degrade` applies (tests and benchmarks/bench_degraded.py).
DEGRADATIONS = ("spikes", "clipped", "hum50", "hum60", "dead", "flipped", "stalled", "held", "drift")


def degrade(records: Records, how: str, *, seed: int = 0, channels: int = 3) -> Records:
    """A copy of ``records`` with one rig fault, as real benches produce them.

    - ``spikes``: a train of one- or two-sample spikes (8× the record's peak, every 37 ms, random sign) on
      ``channels`` channels (record, axis) — electrical interference or a loose connector;
    - ``clipped``: ``channels`` channels clipped at 30 % of their peak (flat tops at the range of an
      over-driven input);
    - ``hum50`` / ``hum60``: mains hum on every channel, 50 (60) Hz and its 2nd and 3rd harmonics at 30, 15
      and 8 % of the records' rms, its phase drifting from record to record, non-decaying;
    - ``dead``: ``channels`` channels reading only a little noise (an unplugged sensor);
    - ``flipped``: ``channels`` channels with the sign inverted (a sensor mounted the other way round, or a
      negative sensitivity);
    - ``stalled``: a stream that stalls and resumes where it stopped — in every record runs of 1–5 copies of a
      frame (every axis and the force) inserted, 10 % of the samples in all, the record cut back to its length
      (every later sample is late);
    - ``held``: a stream that holds its last value while it stalls and loses what came meanwhile — 10 % of the
      samples of every record replaced by the frame before them (runs of 1–3; none within 8 samples of the
      hammer's peak: a record whose hit was lost is no impact record);
    - ``drift``: a DC drift on every channel, a ramp from 0 to ±1…3× the records' rms over the record.

    The channels are drawn at random, one repeat of an angle each where the records repeat an angle.
    """
    rng = np.random.default_rng(seed)
    acc = records.acc.copy()
    r, a, s = acc.shape
    rms = float(np.sqrt(np.mean(acc**2)))
    _, group = np.unique(np.round(records.sensor_angle_deg, 9), return_inverse=True)  # one repeat per angle
    chosen = rng.choice(group.max() + 1, size=min(channels, group.max() + 1), replace=False)
    picks = [(int(rng.choice(np.flatnonzero(group == g))), int(rng.integers(a))) for g in chosen]
    t = np.arange(s) / records.fs_hz
    if how == "spikes":
        for i, j in picks:
            peak = np.abs(acc[i, j]).max()
            for k in np.arange(int(rng.integers(50, 200)), s - 2, int(0.037 * records.fs_hz)):
                w = int(rng.integers(1, 3))
                acc[i, j, k:k + w] += 8 * peak * rng.choice([-1.0, 1.0])
    elif how == "clipped":
        for i, j in picks:
            lim = 0.3 * np.abs(acc[i, j]).max()
            acc[i, j] = np.clip(acc[i, j], -lim, lim)
    elif how in ("hum50", "hum60"):
        f0 = 50.0 if how == "hum50" else 60.0
        for h, amp in ((1, 0.3), (2, 0.15), (3, 0.08)):
            phase = rng.uniform(0, 2 * np.pi, (r, a))
            acc += amp * rms * np.sqrt(2) * np.cos(2 * np.pi * h * f0 * t + phase[..., None])
    elif how == "dead":
        for i, j in picks:
            acc[i, j] = 1e-4 * rms * rng.standard_normal(s)
    elif how == "flipped":
        for i, j in picks:
            acc[i, j] = -acc[i, j]
    elif how in ("stalled", "held"):
        force = None if records.force is None else records.force.copy()
        for i in range(r):
            if how == "stalled":
                idx, k = [], 0
                while len(idx) < s:
                    idx.append(k)
                    if rng.random() < 0.1 / 3:
                        idx += [k] * int(rng.integers(1, 6))
                    k = min(k + 1, s - 1)
                idx = np.array(idx[:s])
            else:
                idx = np.arange(s)
                hit = int(np.argmax(np.abs(records.force[i]))) if records.force is not None else -99
                k = 1
                while k < s:
                    if rng.random() < 0.1 / 2 and abs(k - hit) > 8:  # a record whose hit was lost is no record
                        run = int(rng.integers(1, 4))
                        idx[k:k + run] = idx[k - 1]
                        k += run
                    k += 1
            acc[i] = acc[i][:, idx]
            if force is not None:
                force[i] = force[i][idx]
        from dataclasses import replace

        return replace(records, acc=acc, force=force, source=f"{records.source} ({how})")
    elif how == "drift":
        acc += rng.choice([-1.0, 1.0], (r, a, 1)) * rng.uniform(1.0, 3.0, (r, a, 1)) * rms * (t / t[-1])
    else:
        raise ValueError(f"unknown degradation {how!r}; expected one of {DEGRADATIONS}")
    from dataclasses import replace

    return replace(records, acc=acc, source=f"{records.source} ({how})")
