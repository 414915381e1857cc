"""The one forward model of a rolling acceleration profile: the steady rolling ring read by the sensor (docs/physics.md §4–6).

Everything that simulates what the co-rotating accelerometer reads over one
revolution goes through here — ``ringfit roll``, the test-data generators, the
tread-stiffness fit, the load estimate and the gap diagnosis:

- :class:`ProfileModel` — how the baseline ``gong-rolling`` model (docs/physics.md §6:
  inextensible ring, χ = 1, hysteretic η, radial frictionless tread springs, plain
  sensor axes, per-revolution mean removed) is changed, by composition:

  - ``ring_changes``: ring parameters set to other values (``rotation``: χ);
  - ``ring_model``: the ring form and operator terms added to D_n
    (:class:`ringfit.physics.rolling.RingModel`; ``wave_damping``);
  - ``load_hooks``: extra loads computed from the radial contact solution and
    applied in a second contact solve (``tread_shear``: :class:`ringfit.physics.contact.BrushShearLoad`)
    — the two solves are one ``lax.scan`` of length 2, so the contact solve is compiled once;
  - ``sensor``: the §5 sensor layers (:class:`ringfit.physics.sensor.SensorModel`);
  - ``membrane_compliance``: 1/EA [1/N] (``ring_extensibility``; ``None`` = the ring as given);
  - ``channel_filters``: per-revolution-harmonic gains applied to both channels.

- :func:`profile_channels` — the pure JAX core: channels ``(P, 2, M)`` for a batch of
  operating points (contact solve §4.3–4.4, sensor layers §5, then one spectral stage:
  channel filters, the data's band limit and the recorded-angle offset).
- :func:`simulate_profile` — one operating point → a :class:`~ringfit.io.profiles.Profile`
  (docs/formats.md §3) at any number of angles, with Ω from the encoder rate or V/R_e.

An effect at its null reproduces the baseline (to rounding; the inextensible ring to ~1e-8 relative), which the
gap diagnosis relies on (docs/physics.md §6).

Example (the seed tyre at 60 km/h and 4 kN on a flat road, 360 angles)::

    from ringfit.data import path
    from ringfit.io.tyre import read_tyre
    from ringfit.physics.profile import simulate_profile
    tyre = read_tyre(path("table9.tyre.toml"))
    p = simulate_profile(tyre.ring, tyre.geometry, speed_kmh=60.0, load_n=4000.0, n_points=360)
    p.acc_radial_ms2.min(), p.condition["rotation_hz"]   # -650.8 m/s² at the patch, 8.51 Hz (Ω = V/R_e)
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.params import BAR, RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, RollingSolution, as_traced, solve_rolling
from ringfit.physics.operating import KMH, AbstractRoad, Drum, FlatRoad, OperatingPoint, road_from_drum_diameter, rolling_radius
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel, sensor_signals, shift_angle

#: Compliance floor [1/N]: EA = 1/(c + floor) is 1e12 N at the null of ``ring_extensibility``.
COMPLIANCE_FLOOR = 1e-12


class ProfileModel(eqx.Module):
    """How the baseline rolling-profile model is changed (see the module docstring).

    Immutable; the ``with_*`` methods return a changed copy. Gap effects call them
    from :meth:`ringfit.gap.effects.base.Effect.profile_model`.
    """

    ring_changes: tuple = ()
    ring_model: RingModel = RingModel()
    load_hooks: tuple = ()
    sensor: SensorModel = SensorModel()
    membrane_compliance: object = None
    channel_filters: tuple = ()
    #: fixed-point passes of the load hooks (static): 1 = one step (radial solve → hook loads → solve again, what the
    #: gap diagnosis's ``tread_shear`` and its blind truth use); more iterate the hooks towards their fixed point with
    #: the update relaxed by ``hook_relaxation`` (docs/physics.md §13: the lever brush at a drive/brake slip needs it)
    hook_passes: int = eqx.field(static=True, default=1)
    hook_relaxation: float = eqx.field(static=True, default=1.0)

    def with_ring_changes(self, **changes) -> "ProfileModel":
        """Set ring parameters (``RingParams`` field names, SI) — e.g. ``chi=0.7``."""
        return dataclasses.replace(self, ring_changes=self.ring_changes + tuple(changes.items()))

    def with_operator_term(self, term) -> "ProfileModel":
        """Add an :class:`~ringfit.physics.rolling.AbstractOperatorTerm` to D_n."""
        rm = self.ring_model
        return dataclasses.replace(self, ring_model=dataclasses.replace(rm, terms=rm.terms + (term,)))

    def with_load_hook(self, hook) -> "ProfileModel":
        """Add a load hook ``(solution, ring, geometry) -> (q_w, q_v)`` [N/m] on the grid."""
        return dataclasses.replace(self, load_hooks=self.load_hooks + (hook,))

    def with_sensor(self, **fields) -> "ProfileModel":
        """Change :class:`~ringfit.physics.sensor.SensorModel` fields (``tilt_gain``, ``offset``, ``gravity``, ``corner_hz``)."""
        return dataclasses.replace(self, sensor=dataclasses.replace(self.sensor, **fields))

    def with_membrane_compliance(self, compliance) -> "ProfileModel":
        """Finite membrane stiffness: compliance 1/EA [1/N] (0 = EA of 1e12 N)."""
        return dataclasses.replace(self, membrane_compliance=compliance)

    def with_channel_filter(self, response) -> "ProfileModel":
        """Multiply both channels' revolution harmonics by ``response(omega, ring, geometry, k) -> (K,)`` complex."""
        return dataclasses.replace(self, channel_filters=self.channel_filters + (response,))

    def ring(self, ring: RingParams) -> RingParams:
        """The ring with the model's changes (and EA for the extensible form)."""
        changes = dict(self.ring_changes)
        if self.membrane_compliance is not None:
            changes["ea"] = 1.0 / (self.membrane_compliance + COMPLIANCE_FLOOR)
        return ring.replace(**changes) if changes else ring

    def operator_model(self) -> RingModel:
        """The :class:`~ringfit.physics.rolling.RingModel` actually solved (extensible with a membrane compliance)."""
        if self.membrane_compliance is None:
            return self.ring_model
        return dataclasses.replace(self.ring_model, extensible=True)


class FlatOrDrum(AbstractRoad):
    """A flat road or a drum per operating point, chosen by a traced flag (docs/physics.md §4.3).

    Composes :class:`~ringfit.physics.operating.FlatRoad` and
    :class:`~ringfit.physics.operating.Drum` (``where`` picks one, so the flat road's
    distances are its own bit for bit): one compiled model serves both kinds of road.
    ``diameter`` [m] (ignored where ``is_drum`` is false) and ``is_drum`` have the
    shape of the batch of operating points.
    """

    diameter: jax.Array
    is_drum: jax.Array

    def distance(self, phi, height):
        return jnp.where(self.is_drum, Drum(self.diameter).distance(phi, height), FlatRoad().distance(phi, height))


def flat_or_drum(drum_diameter, P: int) -> FlatOrDrum:
    """:class:`FlatOrDrum` for ``P`` operating points from drum diameters ``(P,)`` [m] (``None`` = flat road)."""
    if drum_diameter is None:
        return FlatOrDrum(diameter=np.ones(P), is_drum=np.zeros(P, dtype=bool))
    d = np.broadcast_to(np.asarray(drum_diameter, dtype=np.float64), (P,))
    return FlatOrDrum(diameter=d.copy(), is_drum=np.isfinite(d) & (d > 0))


def rolling_state(model: ProfileModel, ring: RingParams, geometry: TyreGeometry, operating: OperatingPoint,
                  solver: ContactSolver) -> tuple[RollingSolution, jax.Array]:
    """Steady rolling solution and sensor channels ``(2, M)`` of one operating point (pure JAX).

    ``ring`` is the ring *after* the model's changes (:meth:`ProfileModel.ring`).
    """
    _, sol, channels = rolling_passes(model, ring, geometry, operating, solver)
    return sol, channels


def rolling_passes(model: ProfileModel, ring: RingParams, geometry: TyreGeometry, operating: OperatingPoint,
                   solver: ContactSolver) -> tuple[RollingSolution, RollingSolution, jax.Array]:
    """:func:`rolling_state` with the first (radial) pass: ``(first, solution, channels)``.

    With load hooks, ``first`` is the contact solution the last hook loads were computed from (the pass before the last) (what a brush's
    tip forces, slip and free-rolling radius are read on, docs/physics.md §13); without, it is the solution.
    """
    ring_model = model.operator_model()
    if not model.load_hooks:
        sol = solve_rolling(ring, geometry, operating, model=ring_model, solver=solver)
        first = sol
    else:
        M = solver.n_grid

        # hook_passes fixed-point steps (solve -> hook loads -> solve again …) as one scan of hook_passes + 1
        # solves: the contact solve is traced and compiled once; the loads of step k + 1 are the relaxed
        # (1 − ω)·loads_k + ω·hook(solution_k), ω = hook_relaxation (1: plain steps, the default single step)
        w = model.hook_relaxation
        first_step = jnp.arange(model.hook_passes + 1) == 0

        def step(extra, first):
            s = solve_rolling(ring, geometry, operating, model=ring_model, solver=solver, extra_load=extra)
            loads = [hook(s, ring, geometry) for hook in model.load_hooks]
            new = (sum(q[0] for q in loads), sum(q[1] for q in loads))
            if w == 1.0:
                return new, s
            return tuple(jnp.where(first, n, (1.0 - w) * e + w * n) for n, e in zip(new, extra)), s

        zero = (jnp.zeros(M), jnp.zeros(M))
        _, sols = jax.lax.scan(step, zero, first_step)
        first = jax.tree.map(lambda x: x[-2], sols)
        sol = jax.tree.map(lambda x: x[-1], sols)
    return first, sol, jnp.stack(sensor_signals(sol, geometry, model.sensor))


def spectral_stage(model: ProfileModel, channels, ring, geometry, omega, band, offset):
    """Channel filters, band limit ``(P, M//2+1)`` 0/1 and angle offset [rad] on channels ``(P, 2, M)``."""
    M = channels.shape[-1]
    spec = jnp.fft.rfft(channels, axis=-1) * band[:, None, :]
    k = jnp.arange(M // 2 + 1, dtype=jnp.float64)
    for response in model.channel_filters:
        spec = spec * jax.vmap(lambda om: response(om, ring, geometry, k))(omega)[:, None, :]
    return shift_angle(jnp.fft.irfft(spec, M, axis=-1), offset)


def profile_channels(model: ProfileModel, ring: RingParams, geometry: TyreGeometry, omega, load, roads,
                     band, offset, solver: ContactSolver):
    """Sensor channels of a composed model for a batch of operating points, ``(P, 2, M)`` [m/s²].

    **Arguments:**

    - ``model``: the composed :class:`ProfileModel`; ``ring``: baseline ring (before ``model``'s changes).
    - ``omega``, ``load``: ``(P,)`` Ω [rad/s], Fz [N]; ``roads``: a road with ``(P,)`` leaves.
    - ``band``: ``(P, M//2+1)`` 0/1 mask of the revolution harmonics each measurement holds.
    - ``offset``: recorded-angle offset [rad] (φ = α + offset, docs/physics.md §5 layer 6).

    **Returns:** radial, tangential on φ_j (docs/formats.md §3 signs), as the sensor model reads them.
    """
    ring = model.ring(ring)

    def one(om, fz, road):
        return rolling_state(model, ring, geometry, OperatingPoint(om, fz, road), solver)[1]

    channels = jax.vmap(one)(omega, load, roads)
    return spectral_stage(model, channels, ring, geometry, omega, band, offset)


def full_band(P: int, n_grid: int) -> np.ndarray:
    """Band mask ``(P, M//2+1)`` keeping every harmonic (the model zeroes Nyquist itself)."""
    return np.ones((P, n_grid // 2 + 1))


def _rolling_radius(model, ring, geometry, load, road, solver):
    """R_e = R_out − δ/3 [m] of the standing tyre under ``model`` at ``load`` (traceable; docs/physics.md §4.3)."""
    sol = solve_rolling(ring, geometry, OperatingPoint(0.0, load, road), model=model.operator_model(), solver=solver)
    return rolling_radius(geometry.outer_radius, sol.deflection)


@eqx.filter_jit
def _simulate(model, ring, geometry, speed_or_omega, load, road, offset, solver, from_speed):  # noqa: PLR0913
    """One jit region for :func:`simulate_profile`: Ω (from V/R_e when ``from_speed``), solution, channels."""
    ring = model.ring(ring)
    omega = speed_or_omega / _rolling_radius(model, ring, geometry, load, road, solver) if from_speed \
        else speed_or_omega
    sol, channels = rolling_state(model, ring, geometry, OperatingPoint(omega, load, road), solver)
    channels = spectral_stage(model, channels[None], ring, geometry, omega[None], full_band(1, solver.n_grid),
                              offset)[0]
    return sol, channels, omega


@eqx.filter_jit
def _effective_rolling_radius(model, ring, geometry, load, road, solver):
    return _rolling_radius(model, model.ring(ring), geometry, load, road, solver)


def effective_rolling_radius(ring: RingParams, geometry: TyreGeometry, load_n: float, drum_diameter_m=None, *,
                             model: ProfileModel = ProfileModel(), solver: ContactSolver = ContactSolver()) -> float:
    """R_e = R_out − δ/3 [m] with δ the standing deflection of ``model`` at ``load_n`` (docs/physics.md §4.3).

    What Ω = V/R_e uses when a profile has no encoder rate (docs/formats.md §3).
    """
    road = road_from_drum_diameter(drum_diameter_m)
    return float(_effective_rolling_radius(*as_traced((model, ring, geometry)), np.float64(load_n),
                                           as_traced(road), solver))


def simulate_profile(
    ring: RingParams,
    geometry: TyreGeometry,
    *,
    speed_kmh: float,
    load_n: float,
    rotation_hz: float | None = None,
    drum_diameter_m: float | None = None,
    model: ProfileModel = ProfileModel(),
    solver: ContactSolver = ContactSolver(),
    n_points: int | None = None,
    offset_rad: float = 0.0,
    with_solution: bool = False,
):
    """Simulate the rolling profile the co-rotating sensor reads (docs/physics.md §4–5; docs/formats.md §3).

    **Arguments:**

    - ``ring``, ``geometry``: the tyre; ``speed_kmh``, ``load_n``: the condition.
    - ``rotation_hz``: wheel rotation rate (the encoder's); without it Ω = V/R_e with
      R_e = R_out − δ/3 (:func:`ringfit.physics.operating.rolling_radius`, δ the standing
      deflection of the same model at the same load).
    - ``drum_diameter_m``: a drum of this diameter; ``None`` = flat road.
    - ``model``: the :class:`ProfileModel` (default: the §6 baseline).
    - ``solver``: grid and contact-window settings.
    - ``n_points``: angles of the profile (default: the model grid M), evenly spaced in
      [−180°, 180°), band-limited from the grid.
    - ``offset_rad``: recorded-angle offset (the reading at angle α is the model at α + offset).
    - ``with_solution``: also return the :class:`~ringfit.physics.contact.RollingSolution`.

    **Returns:** a :class:`~ringfit.io.profiles.Profile` whose sidecar condition holds
    ``speed_kmh``, ``load_n``, ``pressure_bar``, ``rotation_hz`` (the Ω used),
    ``revolutions`` (1) and ``drum_diameter_m`` (on a drum); with ``with_solution``,
    ``(profile, solution)``.
    """
    from ringfit.io.profiles import Profile, band_limited_resample, grid_angles_deg

    road = road_from_drum_diameter(drum_diameter_m)
    traced = as_traced((model, ring, geometry))
    from_speed = rotation_hz is None  # Ω = V/R_e, R_e from the standing deflection (same model and load)
    speed_or_omega = speed_kmh * KMH if from_speed else 2.0 * np.pi * float(rotation_hz)
    sol, channels, omega = _simulate(*traced, np.float64(speed_or_omega), np.float64(load_n), as_traced(road),
                                     np.float64(offset_rad), solver, from_speed)
    channels, omega = np.asarray(channels), float(omega)
    points = solver.n_grid if n_points is None else int(n_points)
    values = band_limited_resample(channels, points) if points != channels.shape[-1] else channels
    condition = {"speed_kmh": float(speed_kmh), "load_n": float(load_n),
                 "pressure_bar": float(geometry.pressure) / BAR, "revolutions": 1,
                 "rotation_hz": omega / (2.0 * np.pi)}
    if drum_diameter_m:
        condition["drum_diameter_m"] = float(drum_diameter_m)
    profile = Profile(grid_angles_deg(points), values[0], values[1], condition=condition,
                      source=f"simulated {speed_kmh:g} km/h, {load_n:g} N")
    return (profile, sol) if with_solution else profile


__all__ = ["ProfileModel", "profile_channels", "simulate_profile", "effective_rolling_radius", "rolling_state", "rolling_passes", "spectral_stage", "FlatOrDrum",
           "flat_or_drum", "full_band", "COMPLIANCE_FLOOR"]
