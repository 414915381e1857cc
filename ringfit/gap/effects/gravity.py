"""``gravity`` — the 1 g field seen by a sensor that turns with the wheel (docs/physics.md §5 layer 3, §6).

Rolling profiles only: the specific force ``f = a + g ẑ`` with g = gain ×
9.81 m/s² (``gravity_gain``, null 0 = the baseline's inertial acceleration
only; 1 = standard gravity, other values absorb a calibration error).
Signature: revolution harmonic 1 in both channels, 90° apart, constant
amplitude, dominant at low speed.
"""

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.sensor import STANDARD_GRAVITY


class Gravity(Effect):
    """The ``gravity`` effect: the 1 g field turning with the wheel adds a once-per-revolution sine to both channels.

    This module's docstring has its model and parameters.
    """

    name = "gravity"
    summary = "the 1 g field turning with the wheel adds a once-per-revolution sine to both channels"
    parameters = (
        Parameter("gravity_gain", "-", null=0.0, lo=0.0, hi=1.5, start=1.0, description="g / 9.81 m/s^2"),
    )

    def profile_model(self, values, model):
        return model.with_sensor(gravity=values[0] * STANDARD_GRAVITY)


EFFECT = register(Gravity())
