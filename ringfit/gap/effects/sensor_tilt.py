"""``sensor_tilt`` — the glued sensor turns with the belt slope ψ, mixing the channels (docs/physics.md §5 layers 1 and 4, §6).

Rolling profiles only: sets the tilt gain γ (null 0: fixed radial/tangential
axes, the baseline) and the liner offset e (null 0) of
:class:`ringfit.physics.sensor.SensorModel`. Signature: a tangential
reading ≈ −γΩ²Rψ, antisymmetric about the patch centre, largest at the patch
edges, ∝ Ω²; with e, doublets at the edges.
"""

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter


class SensorTilt(Effect):
    """The ``sensor_tilt`` effect: the sensor axes turn with the belt slope, so radial and tangential readings mix at the patch.

    This module's docstring has its model and parameters.
    """

    name = "sensor_tilt"
    summary = "the sensor axes turn with the belt slope, so radial and tangential readings mix at the patch"
    parameters = (
        Parameter("tilt_gain", "-", null=0.0, lo=0.0, hi=1.1, start=0.8, description="gamma: share of the belt slope the axes follow"),
        Parameter("offset_mm", "mm", null=0.0, lo=0.0, hi=8.0, start=1.0, description="e: sensor inward of the ring centreline"),
    )

    def profile_model(self, values, model):
        return model.with_sensor(tilt_gain=values[0], offset=values[1] * 1e-3)


EFFECT = register(SensorTilt())
