"""``tread_shear`` — tread tips stick to the road and shear in the patch (docs/physics.md §6).

The brush model of :class:`ringfit.physics.contact.BrushShearLoad` *with the lever*
(``lever=True``: the tread element of height τ = R_out − R stays normal to the belt, so
its tip's shear acts on the belt through τ — the term that carries the tread's shear to a
centreline sensor) on top of the radial contact solution, applied as one fixed-point
step: the radial solution gives the shear load, the contact is solved again with it (a
load hook of :class:`ringfit.physics.profile.ProfileModel`). τ comes from the geometry;
the one parameter ``shear_stiffness_mn_per_m2`` = k_x / 1e6 (null 0) is not fixed by any
measured condition, so the effect has a fitted variant only.
"""

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.contact import BrushShearLoad

class TreadShear(Effect):
    """The ``tread_shear`` effect: the tread sticks to the road and shears in the patch, pulling the belt tangentially.

    This module's docstring has its model and parameters.
    """

    name = "tread_shear"
    summary = "the tread sticks to the road and shears in the patch, pulling the belt tangentially"
    parameters = (
        Parameter("shear_stiffness_mn_per_m2", "MN/m^2", null=0.0, lo=0.0, hi=60.0, start=10.0,
                  description="k_x / 1e6: tangential tread stiffness per unit length"),
    )

    def profile_model(self, values, model):
        return model.with_load_hook(BrushShearLoad(values[0] * 1e6, lever=True))


EFFECT = register(TreadShear())
