"""The rolling-profile model of the gap diagnosis: baseline ``gong-rolling`` plus effects by composition (PHYSICS.md §4–6).

:class:`ProfileModel` is what an effect's ``profile_model`` hook receives and
returns: a small immutable record of how the baseline is changed —

- ``ring_changes``: ring parameters set to other values (``rotation``: χ);
- ``terms``: operator terms added to D_n (``wave_damping``), via
  :class:`ringfit.physics.rolling.RingModel` ``terms``;
- ``load_hooks``: extra loads computed from the radial contact solution and
  applied in a second contact solve (``tread_shear``, through
  ``solve_rolling(extra_load=…)``) — the two solves are one ``lax.scan`` of
  length 2, so the contact solve is compiled once;
- ``sensor``: the §5 sensor layers (:class:`ringfit.physics.sensor.SensorModel`:
  ``sensor_tilt``, ``gravity``, ``iepe_highpass``);
- ``membrane_compliance``: 1/EA [1/N] (``ring_extensibility``; ``None`` = the
  inextensible ring of the baseline);
- ``channel_filters``: per-revolution-harmonic gains applied to both channels
  (``sensor_mass``'s mass loading).

:func:`profile_channels` evaluates a composed model for a batch of operating
points: contact solve (:func:`ringfit.physics.contact.solve_rolling`), sensor
layers (:func:`ringfit.physics.sensor.sensor_signals`, per-revolution mean
removed), then one spectral stage — channel filters, the data's band limit
and the recorded-angle offset (:func:`ringfit.physics.sensor.shift_angle`).
Nothing here re-derives the physics; every equation stays in
:mod:`ringfit.physics`.

Exactness of the null: an effect at its null sets a field to the baseline's
own value (χ = 1, γ = e = g = f_c = 0), adds an exactly-zero operator term,
or a unit gain, so the computation is the baseline's. A load hook
(``tread_shear``) at its null adds an exactly-zero load, but through the
two-pass scan — a differently compiled graph — so that null equals the
baseline to rounding (~1e-16 relative), not bit for bit. The other exception is
``ring_extensibility``: the model switches to the extensible 2×2 form with
EA = 1/(c + 1e-12 N⁻¹), i.e. EA = 1e12 N at the null, which equals the
inextensible form to ~1e-8 relative (PHYSICS.md §4.2 test).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp

from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, solve_rolling
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel, sensor_signals, shift_angle

#: Compliance floor [1/N]: EA = 1/(c + floor) is 1e12 N at the null of ``ring_extensibility``.
COMPLIANCE_FLOOR = 1e-12


class ProfileModel(eqx.Module):
    """How the baseline rolling-profile model is changed (see the module docstring).

    Immutable; the ``with_*`` methods return a changed copy. Effects call them
    from :meth:`ringfit.gap.effects.base.Effect.profile_model`.
    """

    ring_changes: tuple = ()
    terms: tuple = ()
    load_hooks: tuple = ()
    sensor: SensorModel = SensorModel()
    membrane_compliance: object = None
    channel_filters: tuple = ()

    def with_ring_changes(self, **changes) -> "ProfileModel":
        """Set ring parameters (``RingParams`` field names, SI) — e.g. ``chi=0.7``."""
        return dataclasses.replace(self, ring_changes=self.ring_changes + tuple(changes.items()))

    def with_operator_term(self, term) -> "ProfileModel":
        """Add an :class:`~ringfit.physics.rolling.AbstractOperatorTerm` to D_n."""
        return dataclasses.replace(self, terms=self.terms + (term,))

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

    def ring_model(self) -> RingModel:
        """The :class:`~ringfit.physics.rolling.RingModel` (form and operator terms)."""
        return RingModel(extensible=self.membrane_compliance is not None, terms=self.terms)


def profile_channels(model: ProfileModel, ring: RingParams, geometry: TyreGeometry, omega, load, roads,
                     band, offset, solver: ContactSolver):
    """Sensor channels of a composed model for a batch of operating points, ``(P, 2, M)`` [m/s²].

    **Arguments:**

    - ``model``: the composed :class:`ProfileModel`; ``ring``: baseline ring (before ``model``'s changes).
    - ``omega``, ``load``: ``(P,)`` Ω [rad/s], Fz [N]; ``roads``: a road with ``(P,)`` leaves (drum) or leafless.
    - ``band``: ``(P, M//2+1)`` 0/1 mask of the revolution harmonics each measurement holds.
    - ``offset``: recorded-angle offset [rad] (φ = α + offset, PHYSICS.md §5 layer 6).

    **Returns:** radial, tangential on φ_j (DATA.md §3 signs), per-revolution mean removed.
    """
    ring = model.ring(ring)
    ring_model = model.ring_model()

    M = solver.n_grid

    def one(om, fz, road):
        op = OperatingPoint(om, fz, road)
        if not model.load_hooks:
            sol = solve_rolling(ring, geometry, op, model=ring_model, solver=solver)
        else:
            # one fixed-point step (radial solve -> hook loads -> solve again) as a two-pass scan:
            # the contact solve is traced and compiled once, not twice
            def step(extra, _):
                sol = solve_rolling(ring, geometry, op, model=ring_model, solver=solver, extra_load=extra)
                loads = [hook(sol, ring, geometry) for hook in model.load_hooks]
                return (sum(q[0] for q in loads), sum(q[1] for q in loads)), sol

            zero = (jnp.zeros(M), jnp.zeros(M))
            _, sols = jax.lax.scan(step, zero, None, length=2)
            sol = jax.tree.map(lambda x: x[1], sols)
        return jnp.stack(sensor_signals(sol, geometry, model.sensor))

    channels = jax.vmap(one)(omega, load, roads)
    spec = jnp.fft.rfft(channels, axis=-1) * band[:, None, :]
    k = jnp.arange(M // 2 + 1, dtype=jnp.float64)
    for response in model.channel_filters:
        spec = spec * jax.vmap(lambda om: response(om, ring, geometry, k))(omega)[:, None, :]
    return shift_angle(jnp.fft.irfft(spec, M, axis=-1), offset)


__all__ = ["ProfileModel", "profile_channels", "COMPLIANCE_FLOOR"]
