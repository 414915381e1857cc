"""``ground_contact`` — the loaded tyre pressed on the ground: modes shift and split into ``extr`` and ``0`` (docs/physics.md §6).

Modal data only. Rows of a loaded (or rolling) table tagged ``extr``/``vert``
take the k-th cosine-type (contact-symmetric) mode of :mod:`ringfit.physics.loaded`,
rows tagged ``0``/``hort`` the k-th sine-type (contact-antisymmetric) one (k = n).
The contact half-angle of each row is ``s · a_row``: ``a_row`` is the patch the
rolling model's static contact solve gives at the row's table load
(:func:`ringfit.gap.modal_conditions.contact_patch`, ``rows.patch``), ``s`` the parameter
``patch_scale`` — null 0 (no patch: eq. 18 exactly), fixed by the measured
condition at 1 (the *computed* candidate: a prediction with no free parameter),
free in the *fitted* candidate (a patch the load does not explain is a finding
too). Changes made by earlier effects in a chain are carried over additively.
"""

import jax
import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.loaded import DEFAULT_HARMONICS, loaded_angular_frequencies
from ringfit.physics.natural import natural_angular_frequencies


class GroundContact(Effect):
    """The ``ground_contact`` effect: tread springs in the contact patch stiffen the cos-type (extr) modes of the loaded tyre.

    This module's docstring has its model and parameters.
    """

    name = "ground_contact"
    summary = "tread springs in the contact patch stiffen the cos-type (extr) modes of the loaded tyre"
    applies_when = "no loaded or rolling table (sidecar `state: loaded`/`rolling` with `load_n` > 0) with rows it can move"
    parameters = (
        Parameter("patch_scale", "-", null=0.0, lo=0.0, hi=3.0, start=1.0, condition=1.0,
                  description="contact half-angle / the half-angle the table's load gives in the contact solve",
                  # the contact solve's half-angle is known to a factor ~1.5 (k_trd, the sidewall); 0.4 … 2.5
                  plausible=(0.4, 2.5)),
    )

    def modal_mask(self, rows):
        # rows of a loaded mode type, and rows the rolling model predicts (with rotation: docs/physics.md §3.7)
        joint = rows.joint_rows()
        typed = (np.asarray(rows.contact) != 0) & (np.asarray(rows.patch) > 0)
        return (typed | joint) & (np.asarray(rows.is_freq) > 0)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        # one eigen-solve per table (a static loop: batched LAPACK eigen-solves under forward-mode
        # differentiation are avoided on purpose), each row picks its mode
        k = jnp.clip(rows.n, 1, DEFAULT_HARMONICS).astype(jnp.int32) - 1
        tables = rows.contact_tables

        def solve(_):
            loaded = jnp.zeros_like(omega)
            for t in range(rows.table_patch.shape[0]) if tables is None else tables:  # tables with a patch only
                cos_t, sin_t = loaded_angular_frequencies(ring, geometry, values[0] * rows.table_patch[t],
                                                          DEFAULT_HARMONICS)
                pick = jnp.where(rows.contact == 1, cos_t[k], sin_t[k])
                loaded = jnp.where(rows.table == t, pick, loaded)
            return loaded

        # at the null (patch_scale 0: every refit without this effect) no eigen-solve is run
        loaded = jax.lax.cond(values[0] > 0, solve, lambda _: jnp.zeros_like(omega), None)
        free = natural_angular_frequencies(ring, geometry, rows.n)
        use = (rows.contact != 0) & (rows.n >= 1) & (rows.patch > 0) & (values[0] > 0)
        return jnp.where(use, omega + (loaded - free), omega), zeta


EFFECT = register(GroundContact())
