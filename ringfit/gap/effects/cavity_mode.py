"""``cavity_mode`` — the acoustic resonance of the air cavity coupled with the ring (docs/physics.md §3.6, §6).

Modal data: per harmonic, the cavity pressure ``P_n = ρ0c²(b/A_c) ω² W_n/(ω_a,n² − ω²)``
loads the ring (``q_w += b P_n``), ``ω_a,n = n·2π f_cav``. With the modal
mass ``m = ρA(n²+1)/n²`` per unit length and ``k = b²ρ0c²/(A_c m)`` the
structural root continues ω₀ as ``ω² = ω₀² + δ``,
``δ² − [(ω_a² − ω₀²) + k] δ − k ω₀² = 0`` (the root that vanishes with k;
:func:`ringfit.physics.natural.cavity_coupling`, :func:`~ringfit.physics.natural.cavity_coupled_shift`).
f_cav is the row of kind ``acoustic`` in the data when there is one (the
uncoupled cavity frequency taken as measured) and eq. 22 (343/1.568 Hz)
otherwise; on a ``loaded`` table the contact flat splits it (:mod:`ringfit.physics.cavity`):
an n = 1 row tagged ``hort``/``0`` meets the lower, fore-aft line ``f_cav √(1 + W_2/h_c)``,
one tagged ``vert``/``extr`` the higher, vertical line ``f_cav √(1 − W_2/h_c)`` (W_2 from the
static contact solve at the table's load); a table whose sidecar says ``pressure_bar = 0``
has no air and is left alone; ρ0 = 1.2 (p0 + p_atm)/p_atm, c = 343 m/s. Parameter
``inverse_area_per_m2`` = 1/A_c (null 0: no coupling). Steady rolling sees
only ~1e-3 of it (docs/physics.md §6): not a profile effect.
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.natural import cavity_coupled_shift, cavity_coupling


class CavityMode(Effect):
    """The ``cavity_mode`` effect: the air cavity's acoustic resonance pulls on the ring modes near it.

    This module's docstring has its model and parameters.
    """

    name = "cavity_mode"
    summary = "the air cavity's acoustic resonance pulls on the ring modes near it"
    parameters = (
        Parameter("inverse_area_per_m2", "1/m^2", null=0.0, lo=0.0, hi=500.0, start=50.0,
                  description="1 / cavity cross-section A_c"),
    )

    def modal_mask(self, rows):
        air = np.broadcast_to(np.asarray(rows.cavity_hz) > 0, np.shape(rows.n))
        return (np.asarray(rows.is_freq) > 0) & (np.asarray(rows.n) >= 1) & air

    def modal(self, values, omega, zeta, rows, ring, geometry):
        # rows.cavity_hz: per row, the line its ring mode meets — on a loaded table the fore-aft or vertical
        # line of the flattened cavity for n = 1 (docs/physics.md §6, ringfit.physics.cavity); 0 = no air
        air = rows.cavity_hz > 0
        nz = (rows.n >= 1) & air
        nn = jnp.where(nz, rows.n, 1.0)
        k = cavity_coupling(ring, geometry, nn, values[0])
        delta = cavity_coupled_shift(omega, 2.0 * jnp.pi * jnp.where(air, rows.cavity_hz, 1.0) * nn, k)
        return jnp.where(nz, jnp.sqrt(jnp.clip(omega * omega + delta, 0.0)), omega), zeta


EFFECT = register(CavityMode())
