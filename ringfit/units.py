"""Unit conversions used across layers, each defined once (NumPy-free, JAX-free; the bottom layer)."""

from __future__ import annotations

#: m/s per km/h.
KMH = 1.0 / 3.6

#: m/s² per g, the unit (standard gravity, exact by definition): converting readings recorded in g.
G_UNIT = 9.80665

#: The gravitational acceleration of the model [m/s²] (docs/physics.md §5 layer 3: the rotating gravity the
#: sensor reads) and of the plots' "g" axes; the 0.03 % from G_UNIT is far below any sensor's calibration.
GRAVITY = 9.81

#: The two-sided 95 % standard-normal quantile: a 95 % interval is the value ± Z95·σ (every interval of ringfit).
Z95 = 1.959963984540054
