"""``ground_contact`` — the loaded tyre pressed on the ground: modes shift and split into ``extr`` and ``0`` (PHYSICS.md §6).

Modal data only. Rows of a loaded (or rolling) table tagged ``extr``/``vert``
take the k-th cosine-type mode of :mod:`ringfit.physics.loaded`, rows tagged
``0``/``hort`` the k-th sine-type mode (k = n). Parameter: the contact
half-angle a [deg] (null 0: no patch, eq. 18 exactly). Its prior is centred
on the half-angle of the Table 9 tyre at 4 kN (11.7°, PHYSICS.md §7) with a
wide spread; ``k_trd`` is the ring's (tyre.toml, default 19e6 N/m²).
Changes made by earlier effects in a chain are carried over additively.
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.loaded import DEFAULT_HARMONICS, loaded_angular_frequencies
from ringfit.physics.natural import natural_angular_frequencies


class GroundContact(Effect):
    name = "ground_contact"
    summary = "tread springs in the contact patch stiffen the cos-type (extr) modes of the loaded tyre"
    parameters = (
        Parameter("half_angle_deg", "deg", null=0.0, lo=0.0, hi=30.0, start=10.0, prior=(11.7, 8.0),
                  description="contact half-angle a of the patch at the test load"),
    )

    def modal_mask(self, rows):
        return (np.asarray(rows.contact) != 0) & (np.asarray(rows.is_freq) > 0)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        a_deg = values[0]
        cos_t, sin_t = loaded_angular_frequencies(ring, geometry, jnp.deg2rad(a_deg), DEFAULT_HARMONICS)
        k = jnp.clip(rows.n, 1, DEFAULT_HARMONICS).astype(jnp.int32) - 1
        loaded = jnp.where(rows.contact == 1, cos_t[k], sin_t[k])
        free = natural_angular_frequencies(ring, geometry, rows.n)
        use = (rows.contact != 0) & (rows.n >= 1) & (a_deg > 0)
        return jnp.where(use, omega + (loaded - free), omega), zeta


EFFECT = register(GroundContact())
