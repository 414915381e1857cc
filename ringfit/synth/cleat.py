"""Synthetic drum tests: a tyre rolling on a drum, with or without a cleat, seen by one co-rotating sensor
(docs/physics.md §9, *the synthetic drum bench*).

:class:`CleatBench` generates continuous recordings (:mod:`ringfit.io.continuous`) with a known truth, so that
the whole chain recording → profile / angle–time field → rolling-tyre modes can be tested: the steady reading
of the rolling ring (or an analytic stand-in), a radial impulse at each cleat pass answered by the rolling,
loaded tyre's modes (``modes="loaded"``, §3.7) or by the free spinning ring's waves (``modes="free"``, a
stand-in), the cleat's enveloping ridge, and the measurement chain (encoder, hall pulses, noise, IEPE
high-pass). Its truth: :meth:`CleatBench.cleat_field`, :meth:`CleatBench.generating_modes`,
:meth:`CleatBench.profile_truth`, :meth:`CleatBench.arrival_times`.

Example (two seconds at 40 km/h, the fast stand-ins)::

    from ringfit.synth.cleat import CleatBench
    bench = CleatBench(steady="analytic", modes="free", speed_kmh=40.0)
    rec = bench.record(2.0)                     # a ContinuousRecord; bench.write(path, 2.0) writes it
    bench.arrival_times(2.0)[:3]                # [0.05, 0.395, 0.739] s: one hit per drum revolution
    bench.generating_modes()["fixed_hz"][:3]    # [107.0, 107.0, 113.2] Hz (n = 1 backward, forward; n = 2 …)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ringfit.io.continuous import DEFAULT_CHUNK, ContinuousRecord, ContinuousWriter
from ringfit.io.profiles import band_limited_resample, grid_angles_deg
from ringfit.io.record_types import Axis
from ringfit.units import GRAVITY as G
from ringfit.units import KMH
#: Deflection of the Table 9 tyre at 4 kN on the 1.2192 m drum (docs/physics.md §7), for R_e.
TABLE9_DRUM_DEFLECTION = 0.01386


@dataclass(frozen=True)
class CleatBench:
    """A drum test bench with a cleat, with every setting of the synthetic truth.

    **Fields** (SI unless the name says otherwise):

    - ``geometry``, ``ring``: the tyre (default Table 9, docs/physics.md §1).
    - ``speed_kmh``, ``load_n``, ``drum_diameter_m``: operating condition.
    - ``load_steps``: ``((t_s, load_n), ...)``: the load changes to ``load_n`` at ``t_s`` (the steady
      reading switches to that load's; ``load_n`` before the first step). Empty: ``load_n`` throughout.
    - ``rolling_radius_m``: R_e (Ω = V/R_e); default ``R_out − δ/3`` with the
      Table 9 drum deflection (:func:`ringfit.physics.operating.rolling_radius`).
    - ``fs_hz``: sample rate.
    - ``orders``: circumferential orders n excited by the cleat (``modes="loaded"``: the modes
      whose dominant order is one of these).
    - ``modes``: ``"free"`` (eq. 25 waves of the free spinning ring: no patch, a stand-in) or ``"loaded"``
      (modes of the rolling ring with the tread springs of the steady patch at ``speed_kmh``, ``load_n``
      and the drum, :attr:`contact_arc`; docs/physics.md §3.7: the model of ``ringfit campbell``).
    - ``impulse_ns``: radial impulse of a cleat hit [N s]; ``rolloff_order``:
      order n_c of the Gaussian roll-off exp(−(n/n_c)²) of the cleat's footprint.
    - ``contact_half_angle_deg``: patch half-angle a of the enveloping ridge (and, ``modes="free"``, of the
      hit at φ_L = −a; ``modes="loaded"`` hits the steady patch's leading edge).
    - ``ridge_ms2``, ``ridge_width_deg``: peak and width of the enveloping ridge.
    - ``noise_ms2``: white noise std per sample and axis.
    - ``highpass_hz``: IEPE corner f_c (0 = none).
    - ``gravity``: include the 1 g field.
    - ``steady``: ``"ring"`` (rolling ring model) or ``"analytic"`` (stand-in).
    - ``encoder``: ``"angle"`` (absolute, ``encoder_counts`` per revolution) or
      ``"pulses"`` (``pulses_per_rev``).
    - ``encoder_offset_deg``: φ = encoder angle + offset (absolute encoder).
    - ``hall_delay_s``: the hall edge comes this long before the cleat arrives.
    - ``start_angle_deg``: sensor angle φ at t = 0; ``first_arrival_s``: time of the first hit.
    - ``axes``: channels to record; ``seed``: noise seed.
    """

    geometry: object = None
    ring: object = None
    speed_kmh: float = 40.0
    load_n: float = 4000.0
    load_steps: tuple = ()
    drum_diameter_m: float = 1.2192
    rolling_radius_m: float | None = None
    fs_hz: float = 25600.0
    orders: tuple = (1, 2, 3, 4, 5, 6, 7, 8)
    modes: str = "free"
    impulse_ns: float = 2.0
    rolloff_order: float = 6.0
    contact_half_angle_deg: float = 11.6
    ridge_ms2: float = 1500.0
    ridge_width_deg: float = 1.5
    noise_ms2: float = 5.0
    highpass_hz: float = 0.3
    gravity: bool = True
    steady: str = "ring"
    encoder: str = "angle"
    encoder_counts: int = 4096
    pulses_per_rev: int = 1024
    encoder_offset_deg: float = -97.0
    hall_delay_s: float = 0.002
    start_angle_deg: float = 20.0
    first_arrival_s: float = 0.05
    axes: tuple = ("radial", "tangential")
    seed: int = 0
    _cache: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self):
        if self.geometry is None or self.ring is None:
            from ringfit.params import table9

            geometry, ring = table9()
            object.__setattr__(self, "geometry", self.geometry or geometry)
            object.__setattr__(self, "ring", self.ring or ring)
        if self.steady not in ("ring", "analytic"):
            raise ValueError(f"steady={self.steady!r}; expected 'ring' or 'analytic'")
        if self.modes not in ("free", "loaded"):
            raise ValueError(f"modes={self.modes!r}; expected 'free' or 'loaded'")
        if self.encoder not in ("angle", "pulses"):
            raise ValueError(f"encoder={self.encoder!r}; expected 'angle' or 'pulses'")

    # ------------------------------------------------------------------ kinematics
    @property
    def radius_e(self) -> float:
        """Effective rolling radius R_e [m]."""
        if self.rolling_radius_m is not None:
            return float(self.rolling_radius_m)
        from ringfit.physics.operating import rolling_radius

        return float(rolling_radius(float(self.geometry.outer_radius), TABLE9_DRUM_DEFLECTION))

    @property
    def omega(self) -> float:
        """Wheel speed Ω = V/R_e [rad/s]."""
        return self.speed_kmh * KMH / self.radius_e

    @property
    def rotation_hz(self) -> float:
        return self.omega / (2.0 * math.pi)

    @property
    def drum_period_s(self) -> float:
        """Time between cleat passes [s]: drum circumference / V."""
        return math.pi * self.drum_diameter_m / (self.speed_kmh * KMH)

    @property
    def circumference_ratio(self) -> float:
        """Drum circumference / tyre rolling circumference (revolutions of the tyre per pass)."""
        return self.drum_diameter_m / (2.0 * self.radius_e)

    @property
    def envelope_s(self) -> float:
        """Time the cleat takes to cross the patch, 2a/Ω [s]."""
        return 2.0 * math.radians(self.contact_half_angle_deg) / self.omega

    def sensor_angle(self, t) -> np.ndarray:
        """Unwrapped sensor angle φ(t) [deg]."""
        return self.start_angle_deg + np.degrees(self.omega) * np.asarray(t, dtype=np.float64)

    def arrival_times(self, duration_s: float) -> np.ndarray:
        """Times of the cleat arrivals at the tyre within ``[0, duration_s)`` [s]."""
        k = np.arange(0, int(math.ceil((duration_s - self.first_arrival_s) / self.drum_period_s)) + 1)
        t = self.first_arrival_s + k * self.drum_period_s
        return t[(t >= 0) & (t < duration_s)]

    def condition(self) -> dict:
        """Condition keys of the record (``speed_kmh``, ``load_n``, ...)."""
        return {
            "speed_kmh": float(self.speed_kmh),
            "load_n": float(self.load_n),
            "pressure_bar": float(self.geometry.pressure) / 1e5,
            "drum_diameter_m": float(self.drum_diameter_m),
            "rotation_hz": float(self.rotation_hz),
        }

    # ------------------------------------------------------------------ cleat response (truth)
    @cached_property
    def _modes(self) -> dict:
        if self.modes == "loaded":
            return self._loaded_modes()
        from ringfit.physics.natural import ring_modal_mass, rotating_natural_frequencies

        n = np.asarray(self.orders, dtype=np.float64)
        f = np.asarray(rotating_natural_frequencies(self.ring, self.geometry, n, self.omega))  # (orders, 2) Hz
        w1, w2 = 2 * np.pi * f[:, 0], 2 * np.pi * f[:, 1]
        zeta = float(self.ring.damping_ratio)
        s = np.stack([1j * w1 - zeta * np.abs(w1), 1j * w2 - zeta * np.abs(w2)], axis=1)  # (orders, 2)
        # Ẇ_n(0+) of a radial impulse I at one point: I/(2πR) per harmonic over ρA(1 + 1/n²), i.e. I/(2 M_n)
        b = self.impulse_ns / (2.0 * np.asarray(ring_modal_mass(self.ring, self.geometry, n))) \
            * np.exp(-((n / self.rolloff_order) ** 2))
        # W_n(t) = b (e^{s1 t} − e^{s2 t}) / (i(ω1 − ω2)); radial reading −∂²w/∂t² with w = Σ 2Re[W_n e^{inθ}]
        sign = np.array([1.0, -1.0])
        coef = -2.0 * b[:, None] * sign[None, :] * s**2 / (1j * (w1 - w2))[:, None]
        # fixed frame: θ − θ0 = φ − φ_L − Ωτ → complex rate s − inΩ
        rate = s - 1j * n[:, None] * self.omega
        return {"n": n, "f_rot": f, "s": s, "coef": coef, "rate": rate}

    def _loaded_modes(self) -> dict:
        """Impulse response of the rolling ring with the patch, by modal superposition (docs/physics.md §3.7).

        The modes are the one model of the rolling, loaded tyre, the model ``ringfit campbell``, ``cleat --ssi
        --tyre`` labelling and the diagnosis's rolling rows use:
        :func:`ringfit.physics.rolling_modes.loaded_rolling_modes` at this bench's Ω, load and drum (the tread
        springs on the patch of the steady rolling solution, :data:`~ringfit.physics.rolling_modes.DEFAULT_HARMONICS`
        harmonics), labelled from their radial acceleration content as the Campbell diagram labels them
        (:func:`ringfit.physics.campbell.acceleration_labels`). The cleat hits the leading edge of that patch.
        """
        import jax

        from ringfit.physics.campbell import acceleration_labels
        from ringfit.physics.rolling_modes import gyroscopic_matrices, harmonic_basis, rolling_modes_jit

        arc = self.contact_arc  # loaded_rolling_modes = contact_arc, then rolling_modes on that arc
        model = jax.device_get(rolling_modes_jit(self.ring, self.geometry, self.omega, arc))
        K = (model.k.size - 1) // 2
        M, Gm, Km, _, kd = (np.asarray(x) for x in gyroscopic_matrices(self.ring, self.geometry, self.omega, arc,
                                                                     harmonics=K))
        k = np.asarray(model.k)
        b = np.asarray(harmonic_basis(k, False))[:, :, 0]  # (H, 2): (W_k, V_k) = b_k q_k
        R = float(self.geometry.radius)
        # radial impulse at the patch's leading edge φ_L, footprint roll-off exp(−(k/n_c)²), per unit length
        lead = float(arc.leading)
        Q = self.impulse_ns / (2 * np.pi * R) * np.exp(-1j * k * lead) * np.exp(-((k / self.rolloff_order) ** 2))
        f = np.conj(b[:, 0]) * Q
        d = k.size
        Minv = np.linalg.inv(M)
        A = np.block([[np.zeros((d, d)), np.eye(d)], [-Minv @ Km, -Minv @ Gm]])
        lam, vec = np.linalg.eig(A)
        coef = np.linalg.solve(vec, np.concatenate([np.zeros(d), Minv @ f]))
        pos = lam.imag > 0
        lam, vec, coef = lam[pos], vec[:d, pos], coef[pos]
        w = lam.imag
        # each positive-frequency pole ↔ the model mode at the same ω: its damping ratio and labels
        mi = np.argmin(np.abs(w[:, None] - np.asarray(model.angular_frequency)[None, :]), axis=1)
        rate = 1j * w - np.asarray(model.damping_ratio)[mi] * w
        q = vec * coef[None, :]  # (H, modes): modal amplitude of q_k
        mu = rate[None, :] + 1j * k[:, None] * self.omega  # rate the material sees at harmonic k
        acc_r = -(mu**2) * b[:, 0:1] * q  # radial acceleration content (H, modes)
        acc_t = -(mu**2) * b[:, 1:2] * q
        order, travel, symmetry, _, _ = (np.asarray(x) for x in jax.device_get(acceleration_labels(model)))
        radial = np.sum(np.abs(np.asarray(model.radial)) ** 2, axis=-1) > 1e-12
        order, travel, symmetry = order[mi], travel[mi], symmetry[mi]
        keep = np.isin(order, np.asarray(self.orders)) & radial[mi]
        # the two strongest signed harmonics of each mode's radial acceleration content and their shares
        share = np.abs(acc_r[:, keep]) ** 2
        share = share / share.sum(axis=0, keepdims=True)
        top = np.argsort(-share, axis=0)[:2]
        # spatial patterns on a fine grid φ_j = −π + 2πj/L for fast interpolation (2 Re: the conjugate poles)
        L = 4096
        phi = np.radians(grid_angles_deg(L))
        basis = np.exp(1j * np.outer(k, phi))  # (H, L)
        tables = {"radial": 2.0 * (acc_r[:, keep].T @ basis), "tangential": 2.0 * (acc_t[:, keep].T @ basis)}
        return {"n": order[keep], "travel": travel[keep], "symmetry": symmetry[keep], "rate": rate[keep],
                "tables": tables, "harmonics": k[top].T.astype(int),
                "shares": np.take_along_axis(share, top, axis=0).T}

    @cached_property
    def contact_arc(self):
        """The linearised contact of ``modes="loaded"`` (:class:`ringfit.physics.rolling_modes.ContactArc`): the
        tread springs on the patch of the steady rolling solution at this bench's Ω, load and drum
        (:func:`ringfit.physics.rolling_modes.contact_arc`, docs/physics.md §3.7, §4.3–4.4)."""
        import jax

        from ringfit.physics.operating import Drum, OperatingPoint
        from ringfit.physics.rolling_modes import contact_arc

        op = OperatingPoint(omega=self.omega, load=float(self.load_n), road=Drum(diameter=self.drum_diameter_m))
        arc, sol = contact_arc(self.ring, self.geometry, op)
        if not bool(sol.ok):
            raise ValueError(f"the steady contact solve at {self.load_n:g} N, {self.speed_kmh:g} km/h did not converge")
        return jax.device_get(arc)

    def generating_modes(self) -> dict:
        """The travelling waves the cleat excites, as seen by a fixed observer (the angle–time field).

        **Returns** a dict of arrays, one entry per (order, branch):
        ``n``, ``branch`` (``backward``/``forward``), ``rotating_hz`` (eq. 25,
        signed), ``fixed_hz`` (eq. 26, |ω_nk − nΩ|/2π, what the field's time
        series oscillate at), ``decay_per_s`` (σ), ``damping_fixed`` (σ/|ω_fixed|,
        the damping ratio SSI sees on the field). With ``modes="loaded"``: one entry
        per mode, ``n`` its dominant order and ``branch`` its direction
        (``backward``/``forward``/``standing``) in the radial acceleration content,
        ``tag`` (``extr``/``0``, ``vert``/``hort``) for standing modes, ``rotating_hz`` NaN, and
        ``harmonics``/``shares`` ``(modes, 2)``: the two strongest signed harmonics k of the mode's radial
        acceleration content (k > 0 backward) and their shares of it (docs/physics.md §3.7: a hybrid of
        the forward wave of n and the backward waves of n and n + 2 shows both).
        """
        m = self._modes
        if self.modes == "loaded":
            from ringfit.targets.rolling_modes import TRAVELLING_RATIO

            rate = m["rate"]
            direction = np.where(m["travel"] >= TRAVELLING_RATIO, "backward",
                                 np.where(m["travel"] <= -TRAVELLING_RATIO, "forward", "standing"))
            cos_type = m["symmetry"] >= 0.5
            tag = np.where(m["n"] == 1, np.where(cos_type, "vert", "hort"), np.where(cos_type, "extr", "0"))
            return {
                "n": m["n"].astype(int), "branch": direction, "tag": np.where(direction == "standing", tag, ""),
                "rotating_hz": np.full(rate.size, np.nan), "fixed_hz": np.abs(rate.imag) / (2 * np.pi),
                "decay_per_s": -rate.real, "damping_fixed": -rate.real / np.abs(rate),
                "harmonics": m["harmonics"], "shares": m["shares"],
            }
        n = np.repeat(m["n"], 2)
        rate = m["rate"].ravel()
        return {
            "n": n.astype(int),
            "branch": np.tile(np.array(["backward", "forward"]), len(m["n"])),
            "rotating_hz": m["f_rot"].ravel(),
            "fixed_hz": np.abs(rate.imag) / (2 * np.pi),
            "decay_per_s": -rate.real,
            "damping_fixed": -rate.real / np.abs(rate),
        }

    def cleat_field(self, phi_deg, tau_s, axis: Axis = "radial") -> np.ndarray:
        """Truth of the cleat response in the angle–time plane [m/s²] (before noise and high-pass).

        **Arguments:** ``phi_deg`` sensor angle φ [deg] (any real value),
        ``tau_s`` time since the cleat's arrival [s] (0 for τ < 0), broadcast together.
        ``axis``: ``radial`` (inward +) or ``tangential`` (along travel +; the
        inextensible ring's v = (i/n) w part; no ridge).
        """
        phi = np.radians(np.asarray(phi_deg, dtype=np.float64))
        tau = np.asarray(tau_s, dtype=np.float64)
        phi, tau = np.broadcast_arrays(phi, tau)
        out = np.zeros(phi.shape)
        on = tau >= 0
        if not on.any():
            return out
        p = phi[on] + math.radians(self.contact_half_angle_deg)  # φ − φ_L
        t = tau[on]
        m = self._modes
        acc = np.zeros(p.shape)
        if axis not in ("radial", "tangential"):
            raise ValueError(f"axis={axis!r}; cleat_field has radial and tangential")
        if self.modes == "loaded":  # modal superposition: Re(S_j(φ) e^{rate_j τ}), S_j tabulated
            for j, r in enumerate(m["rate"]):
                tab = m["tables"][axis][j]
                e = np.exp(r * t)
                acc += _interp_periodic(np.degrees(phi[on]), tab.real) * e.real
                acc -= _interp_periodic(np.degrees(phi[on]), tab.imag) * e.imag
        else:
            for i, n in enumerate(m["n"]):
                for k in range(2):
                    c = m["coef"][i, k] if axis == "radial" else (-1j / n) * m["coef"][i, k]
                    r = m["rate"][i, k]
                    acc += np.abs(c) * np.exp(r.real * t) * np.cos(n * p + r.imag * t + np.angle(c))
        if axis == "radial" and self.ridge_ms2 > 0:
            env = self.envelope_s
            inside = t < env
            if inside.any():
                d = (p[inside] - self.omega * t[inside] + np.pi) % (2 * np.pi) - np.pi
                acc[inside] += (
                    self.ridge_ms2
                    * np.sin(np.pi * t[inside] / env)
                    * np.exp(-0.5 * (d / math.radians(self.ridge_width_deg)) ** 2)
                )
        out[on] = acc
        return out

    # ------------------------------------------------------------------ steady rolling
    def load_at(self, t) -> np.ndarray:
        """Load [N] at times ``t`` [s] (``load_n`` before the first of ``load_steps``)."""
        t = np.asarray(t, dtype=np.float64)
        out = np.full(t.shape, float(self.load_n))
        for t0, load in sorted(self.load_steps):
            out = np.where(t >= t0, float(load), out)
        return out

    def _steady_table(self, load: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(radial, tangential) specific-force readings on a fine grid φ_j = −180 + 360 j/M [m/s²], DC kept."""
        load = float(self.load_n if load is None else load)
        if ("table", load) in self._cache:
            return self._cache[("table", load)]
        if self.steady == "ring":
            from ringfit.physics.contact import ContactSolver, solve_rolling_jit
            from ringfit.physics.operating import Drum, OperatingPoint
            from ringfit.physics.sensor import STANDARD_GRAVITY, SensorModel, sensor_signals_jit

            op = OperatingPoint(omega=self.omega, load=load, road=Drum(diameter=self.drum_diameter_m))
            sol = solve_rolling_jit(self.ring, self.geometry, op, solver=ContactSolver(n_grid=2048))
            sensor = SensorModel(gravity=STANDARD_GRAVITY if self.gravity else 0.0, tilt_gain=1.0, remove_mean=False)
            rad, tan = (np.asarray(x) for x in sensor_signals_jit(sol, self.geometry, sensor))
        else:
            rad, tan = self._analytic_steady(2048)
        # band-limited refinement (zero-padded spectrum) so that linear interpolation is accurate
        fine = 16384
        table = tuple(band_limited_resample(x, fine) for x in (rad, tan))
        self._cache[("table", load)] = table
        return table

    def _analytic_steady(self, m: int):
        """Smooth stand-in for the rolling model: patch dip with edge peaks, edge doublets, gravity."""
        phi = np.radians(grid_angles_deg(m))
        a = math.radians(self.contact_half_angle_deg)
        w = math.radians(2.5)
        c = self.omega**2 * self.radius_e
        box = 0.5 * (np.tanh((phi + a) / (0.3 * w)) - np.tanh((phi - a) / (0.3 * w)))
        bump = np.exp(-0.5 * ((phi + a + w) / w) ** 2) + 0.95 * np.exp(-0.5 * ((phi - a - w) / w) ** 2)
        wave = 0.04 * np.cos(6 * phi) * np.exp(-np.abs(phi) / 0.8)
        rad = c * (1.0 - box + 0.3 * bump + wave)
        doublet = (phi + a) / w * np.exp(-0.5 * ((phi + a) / w) ** 2) - (phi - a) / w * np.exp(-0.5 * ((phi - a) / w) ** 2)
        tan = 0.1 * c * doublet
        if self.gravity:
            rad = rad + G * np.cos(phi)
            tan = tan + G * np.sin(phi)
        return rad, tan

    def steady_reading(self, phi_deg, axis: Axis = "radial", t=None) -> np.ndarray:
        """Steady sensor reading at φ [deg] (at times ``t`` [s] with ``load_steps``) before the high-pass
        (DC included) [m/s²]."""
        phi_deg = np.asarray(phi_deg, dtype=np.float64)
        if not self.load_steps or t is None:
            return _interp_periodic(phi_deg, self._steady_table()[_axis_index(axis)])
        loads = np.broadcast_to(self.load_at(t), phi_deg.shape)
        out = np.empty(phi_deg.shape)
        for load in np.unique(loads):
            m = loads == load
            out[m] = _interp_periodic(phi_deg[m], self._steady_table(load)[_axis_index(axis)])
        return out

    def profile_truth(self, angle_deg, axis: Axis = "radial") -> np.ndarray:
        """The rolling profile the sensor reports at ``angle_deg`` [m/s²] (docs/formats.md §3: high-pass included).

        The steady reading is periodic with period 2π/Ω, so the IEPE high-pass
        multiplies revolution harmonic k by H(ikΩ) (docs/physics.md §5 layer 5).
        """
        table = self._steady_table()[_axis_index(axis)]
        if self.highpass_hz > 0:
            from ringfit.physics.sensor import highpass_response

            spec = np.fft.rfft(table)
            spec *= np.asarray(highpass_response(self.omega, self.highpass_hz, spec.size))
            table = np.fft.irfft(spec, table.size)
        return _interp_periodic(np.asarray(angle_deg, dtype=np.float64), table)

    # ------------------------------------------------------------------ recording
    def _raw_chunk(self, i0: int, i1: int, arrivals: np.ndarray | None, rng) -> tuple:
        """Sensor signals before the high-pass, encoder and hall for samples i0:i1."""
        t = np.arange(i0, i1) / self.fs_hz
        phi = self.sensor_angle(t)
        acc = np.empty((len(self.axes), t.size))
        tau = None
        if arrivals is not None and arrivals.size:
            k = np.searchsorted(arrivals, t, side="right") - 1
            tau = np.where(k >= 0, t - arrivals[np.maximum(k, 0)], -1.0)
        for j, axis in enumerate(self.axes):
            if axis == "lateral":
                acc[j] = 0.0
            else:
                acc[j] = self.steady_reading(phi, axis, t)
                if tau is not None:
                    acc[j] += self.cleat_field(phi, tau, axis)
        if self.noise_ms2 > 0:
            acc += rng.normal(0.0, self.noise_ms2, acc.shape)
        if self.encoder == "angle":
            q = 360.0 / self.encoder_counts
            enc = np.round(((phi - self.encoder_offset_deg) % 360.0) / q) * q % 360.0
        else:
            alpha = (phi - self._pulse_reference()) * self.pulses_per_rev / 360.0
            enc = ((alpha - np.floor(alpha)) < 0.5).astype(np.uint8)
        hall = None
        if arrivals is not None:
            edges = arrivals - self.hall_delay_s  # 50 % crossings of the hall's rising edges
            rise, width = 2.0 / self.fs_hz, 1e-3
            k = np.searchsorted(edges, t + 0.5 * rise, side="right") - 1
            d = np.where(k >= 0, t - edges[np.maximum(k, 0)], np.inf)
            level = np.where(d < width, np.clip(0.5 + d / rise, 0.0, 1.0), 0.0)
            hall = 5.0 * level + rng.normal(0.0, 0.02, t.size)
        return acc, enc, hall

    def _pulse_reference(self) -> float:
        """Angle reference of the incremental encoder's pulse train [deg]."""
        return 0.123

    @property
    def pulse_offset_deg(self) -> float:
        """encoder_offset_deg of a pulse record: φ at the first rising edge minus one pulse."""
        q = 360.0 / self.pulses_per_rev
        alpha0 = (self.start_angle_deg - self._pulse_reference()) / q
        first = (math.floor(alpha0) + 1) * q + self._pulse_reference()
        return first - q

    def _highpass(self):
        from scipy import signal

        wc = 2 * math.pi * self.highpass_hz
        return signal.bilinear([1.0, 0.0], [1.0, wc], self.fs_hz)

    def _initial_filter_state(self):
        """High-pass state after a pre-roll of the steady signal (the periodic steady state)."""
        from scipy import signal

        b, a = self._highpass()
        n_pre = int(math.ceil(6.0 / (2 * math.pi * self.highpass_hz) * self.fs_hz))
        t = np.arange(-n_pre, 0) / self.fs_hz
        phi = self.sensor_angle(t)
        zi = []
        for axis in self.axes:
            x = self.steady_reading(phi, axis, t) if axis != "lateral" else np.zeros(t.size)
            _, z = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])
            zi.append(z)
        return zi

    def iter_chunks(self, duration_s: float, *, cleat: bool = True, chunk: int = DEFAULT_CHUNK):
        """Yield ``(acc, encoder, hall)`` chunks of a recording of ``duration_s`` (hall None without cleat)."""
        from scipy import signal

        samples = int(round(duration_s * self.fs_hz))
        arrivals = self.arrival_times(duration_s + self.drum_period_s) if cleat else None
        hp = self.highpass_hz > 0
        if hp:
            b, a = self._highpass()
            zi = self._initial_filter_state()
        for ci, i0 in enumerate(range(0, samples, chunk)):
            i1 = min(i0 + chunk, samples)
            rng = np.random.default_rng([self.seed, ci])
            acc, enc, hall = self._raw_chunk(i0, i1, arrivals, rng)
            if hp:
                for j in range(acc.shape[0]):
                    acc[j], zi[j] = signal.lfilter(b, a, acc[j], zi=zi[j])
            yield acc, enc, hall

    def _record_keys(self, cleat: bool) -> dict:
        pulses = self.encoder == "pulses"
        return dict(
            axes=self.axes,
            fs_hz=self.fs_hz,
            pulses_per_rev=self.pulses_per_rev if pulses else None,
            encoder_offset_deg=self.pulse_offset_deg if pulses else self.encoder_offset_deg,
            hall_delay_s=self.hall_delay_s if cleat else 0.0,
            condition=self.condition(),
        )

    def record(self, duration_s: float, *, cleat: bool = True) -> ContinuousRecord:
        """An in-memory recording (short durations; see :meth:`write` for long ones)."""
        parts = list(self.iter_chunks(duration_s, cleat=cleat))
        acc = np.concatenate([p[0] for p in parts], axis=1)
        enc = np.concatenate([p[1] for p in parts])
        hall = np.concatenate([p[2] for p in parts]) if cleat else None
        keys = self._record_keys(cleat)
        return ContinuousRecord(
            acc=acc,
            encoder_angle_deg=enc if self.encoder == "angle" else None,
            encoder_pulses=enc if self.encoder == "pulses" else None,
            hall=hall,
            source=f"<synthetic {'cleat' if cleat else 'rolling'} {self.speed_kmh:g} km/h>",
            **keys,
        )

    def write(self, path, duration_s: float, *, cleat: bool = True, chunk: int = DEFAULT_CHUNK,
              acc_dtype=np.float64, overwrite: bool = False, progress: bool = False):
        """Stream a recording of ``duration_s`` to ``path`` in chunks (bounded memory); returns the path."""
        from tqdm import tqdm

        samples = int(round(duration_s * self.fs_hz))
        keys = self._record_keys(cleat)
        bar = tqdm(total=samples, unit="sample", unit_scale=True, disable=not progress, desc="synthesising")
        with ContinuousWriter(path, samples=samples, encoder=self.encoder, hall=cleat, acc_dtype=acc_dtype,
                              overwrite=overwrite, **keys) as w:
            for acc, enc, hall in self.iter_chunks(duration_s, cleat=cleat, chunk=chunk):
                w.write(acc, encoder=enc, hall=hall)
                bar.update(acc.shape[1])
        bar.close()
        return path


def _axis_index(axis: str) -> int:
    if axis == "radial":
        return 0
    if axis == "tangential":
        return 1
    raise ValueError(f"axis={axis!r}; expected 'radial' or 'tangential'")


def _interp_periodic(phi_deg: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Linear interpolation of a table on φ_j = −180 + 360 j/M at any angle [deg]."""
    m = table.size
    grid = grid_angles_deg(m)
    return np.interp(phi_deg, grid, table, period=360.0)
