"""Units the project reads besides SI, and the factor that takes each to its SI unit.

Everything inside the project is in SI units and radians; a file may declare a column in one of
these units (:mod:`marine_envs.recording`), and is converted once, when it is read. The
plausibility checks (:mod:`marine_envs.plausibility`) name the likeliest of them behind a value
that looks like a unit mistake.
"""

from __future__ import annotations

import math

#: Non-SI units accepted in the metadata: unit -> (SI unit, factor to multiply by).
UNIT_CONVERSIONS: dict[str, tuple[str, float]] = {
    "ms": ("s", 1e-3),
    "min": ("s", 60.0),
    "deg": ("rad", math.pi / 180),
    "deg/s": ("rad/s", math.pi / 180),
    "deg/s^2": ("rad/s^2", math.pi / 180),
    "kn": ("m/s", 1852 / 3600),
    "knot": ("m/s", 1852 / 3600),
    "knots": ("m/s", 1852 / 3600),
    "km/h": ("m/s", 1 / 3.6),
    "mm": ("m", 1e-3),
    "cm": ("m", 1e-2),
    "km": ("m", 1e3),
}


__all__ = ["UNIT_CONVERSIONS"]
