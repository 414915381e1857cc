"""``iepe_highpass`` — AC coupling of an IEPE sensor and its DAQ (docs/physics.md §5 layer 5, §6).

Rolling profiles only: first-order high-pass ``s/(s + 2πf_c)`` on every
revolution harmonic; ``corner_hz`` null 0 = no filter (the baseline).
Signature: phase lead and gain loss of the once-per-revolution content and
a tilted baseline at low speed; negligible above ~10 km/h for f_c ≲ 0.3 Hz.
"""

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter


class IEPEHighpass(Effect):
    """The ``iepe_highpass`` effect: the sensor's AC coupling filters the slow once-per-revolution content.

    This module's docstring has its model and parameters.
    """

    name = "iepe_highpass"
    summary = "the sensor's AC coupling filters the slow once-per-revolution content"
    parameters = (
        Parameter("corner_hz", "Hz", null=0.0, lo=0.0, hi=3.0, start=0.3, description="high-pass corner f_c"),
    )

    def profile_model(self, values, model):
        return model.with_sensor(corner_hz=values[0])


EFFECT = register(IEPEHighpass())
