"""Plausibility: values that are valid but far outside what a model was built for.

A value that breaks a rule (a negative time step, NaN) raises ``ValueError`` where it enters.
A value that is legal but implausible (a 300 m sea, a rudder of 35 rad) is most often a unit
mistake; it is let through with a :class:`PlausibilityWarning` that names the value, the range
it is compared with and the likely mistake, so that a run never diverges or misleads silently.
"""

from __future__ import annotations

import inspect
import math
import warnings
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from .units import UNIT_CONVERSIONS

if TYPE_CHECKING:
    from .models import VehicleModel

TWO_PI = 2 * math.pi
#: An environment argument more than this many times its default is far outside the range the
#: model was built (and its defaults chosen) for.
FAR_FROM_DEFAULT = 10.0
#: Environment arguments that set a scale (s, m, m/s), compared with their defaults.
SCALE_ARGUMENTS = ("dt", "hs", "wind_speed", "wind_gust", "current_std")
#: Environment arguments that are angles, rad.
ANGLE_ARGUMENTS = ("wave_heading", "wind_direction", "course")
#: Environment arguments mapping state names to values (set-points), checked for angles.
REFERENCE_ARGUMENTS = ("setpoint", "reference")
#: Recorded inputs more than this many times the model's input bound are implausible.
BEYOND_BOUND = 2.0
#: Channels that are headings: unwrapped over many turns they may exceed 2 pi.
HEADINGS = ("psi",)
#: A rotation rate beyond this, rad/s (half a turn a second), is beyond every vehicle of the
#: catalogue: the simulated records' largest is 0.11 rad/s (a USV's roll rate), so a rate
#: recorded in deg/s and declared rad/s shows here from 3.1 deg/s on.
MAX_RATE = math.pi
#: A ratio between an angle's change and its rate's integral within this factor of 180 / pi is
#: a degree slip beyond doubt (LQR records of ``marine simulate``, seeds 1 and 2: 0.99-1.01,
#: the ROV's roll 0.87 through its nonlinear kinematics; either in degrees: 56-58 or 1/58).
DEGREE_SLIP = 1.25
#: Units of the scale arguments, for the messages.
_UNITS = {"dt": "s", "hs": "m", "wind_speed": "m/s", "wind_gust": "m/s", "current_std": "m/s"}
DEGREE = math.pi / 180
#: An angle's change is compared with its rate's integral over spans of these many seconds
#: (the best correlated): a USV's roll correlates best over 1 s (0.99), a hovercraft's slow
#: turns over 10 s (0.94; 0.49 over 1 s).
RATIO_WINDOWS = (1.0, 3.0, 10.0)
#: Below this correlation between an angle's change and its rate's integral the two say
#: nothing about each other's unit.
MIN_CORRELATION = 0.5


class PlausibilityWarning(UserWarning):
    """A value is valid but far outside the range its model was built for: a unit mistake?"""


def warn(messages: Iterable[str], stacklevel: int = 2) -> None:
    """Issue each message as a :class:`PlausibilityWarning` (``stacklevel`` as in
    :func:`warnings.warn`, counted from the caller of this function)."""
    for message in messages:
        warnings.warn(message, PlausibilityWarning, stacklevel=stacklevel + 1)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool) and math.isfinite(float(value))


def environment_arguments(make_simulator: Callable[..., Any], kwargs: Mapping[str, Any]
                          ) -> list[str]:
    """Why the environment arguments ``kwargs`` of ``make_simulator`` look implausible (one
    message each), or ``[]``: a scale (:data:`SCALE_ARGUMENTS`: time step, wave height, wind,
    current) more than :data:`FAR_FROM_DEFAULT` times the environment's default, an angle
    argument or a set-point angle beyond 2 pi rad (degrees given as radians?)."""
    defaults = {name: p.default for name, p in inspect.signature(make_simulator)
                .parameters.items() if p.default is not inspect.Parameter.empty}
    out = []
    for name in SCALE_ARGUMENTS:
        value, default = kwargs.get(name), defaults.get(name)
        if _is_number(value) and _is_number(default) and default > 0 \
                and value > FAR_FROM_DEFAULT * default:
            out.append(f"{name}={value:g} {_UNITS[name]} is {value / default:.0f}x the "
                       f"environment's default {default:g} {_UNITS[name]}: far outside the "
                       "range the model was built for (expect a diverging or meaningless run)")
    for name in ANGLE_ARGUMENTS:
        value = kwargs.get(name)
        if _is_number(value) and abs(value) > TWO_PI:
            out.append(f"{name}={value:g} rad is beyond 2 pi: degrees given as rad?")
    for name in REFERENCE_ARGUMENTS:
        reference = kwargs.get(name)
        if isinstance(reference, Mapping):
            out += [f"{name} {key}={value:g} rad is beyond 2 pi: degrees given as rad?"
                    for key, value in reference.items()
                    if str(key).startswith(("psi", "phi", "theta")) and _is_number(value)
                    and abs(value) > TWO_PI]
    return out


def recorded_values(name: str, values: np.ndarray, si_unit: str, declared: str | None,
                    bound: float | None = None) -> str:
    """Why a recorded column (SI units, after conversion from its ``declared`` unit) looks
    like a unit mistake, or ``""``.

    :param name: the column.  :param values: its values in SI units (NaN = missing).
    :param si_unit: its SI unit.  :param declared: the unit the file declared (None: SI).
    :param bound: the model's bound on its magnitude (an input's limit), or None.
    """
    finite = np.abs(values[np.isfinite(values)])
    if not finite.size:
        return ""
    peak = float(finite.max())
    declared = declared or si_unit
    if bound is not None and bound > 0 and peak > BEYOND_BOUND * bound:
        return (f"{name}: {peak:.3g} exceeds the model's bound {bound:.3g} {si_unit} by "
                f"{peak / bound:.0f}x: {_unit_hint(si_unit, declared, peak, bound)}")
    if bound is not None and bound > 0 and declared == "deg" and si_unit == "rad" \
            and 0.05 * bound < peak / DEGREE <= BEYOND_BOUND * bound:
        # the numbers as written already fit the bound in radians
        return (f"{name}: {peak:.3g} rad is {peak / bound:.1%} of the model's bound "
                f"{bound:.3g} rad: radians declared as deg?")
    # a heading may be unwrapped over many turns (a hovercraft spinning): see angle_rate
    if si_unit == "rad" and peak > TWO_PI and not name.startswith(HEADINGS):
        return (f"{name}: {peak:.3g} rad exceeds 2 pi: "
                f"{'degrees declared as rad' if declared == 'rad' else 'a unit mistake'}?")
    if si_unit == "rad/s" and peak > MAX_RATE:
        return (f"{name}: {peak:.3g} rad/s exceeds {MAX_RATE:.3g} rad/s (half a turn a second), "
                f"beyond what a vessel turns at: "
                f"{'deg/s declared as rad/s' if declared == 'rad/s' else 'a unit mistake'}?")
    return ""


def rate_pairs(vehicle: VehicleModel) -> list[tuple[str, str]]:
    """The (angle, rate) pairs of ``vehicle``'s states: an angle (rad) whose linearised
    equation is its rate (rad/s) alone, e.g. the USV's (psi, r) and (phi, p)."""
    A, B, E = vehicle.linearize()
    names, units = vehicle.state_names, vehicle.state_units
    pairs = []
    for i, angle in enumerate(names):
        terms = np.flatnonzero(A[i])
        if len(terms) == 1 and A[i, terms[0]] == 1 and not B[i].any() and not E[i].any() \
                and units[i] == "rad" and units[terms[0]] == "rad/s":
            pairs.append((angle, names[terms[0]]))
    return pairs


def angle_rate_ratio(angle: np.ndarray, rate: np.ndarray, time: np.ndarray) -> float | None:
    """How many times a recorded ``angle``'s change (rad, unwrapped) exceeds the integral of its
    ``rate`` (rad/s) over the same spans (least squares over every span of the length of
    :data:`RATIO_WINDOWS` where the two correlate best), or None where they do not correlate
    (too little motion over the sensors' noise to tell). Integrating over a span averages the
    rate's noise out; a short span keeps an oscillation (a roll) whole, a long one sees a slow
    turn over the heading's noise."""
    keep = np.isfinite(angle) & np.isfinite(rate)
    if keep.sum() < 10:
        return None
    t, turn = time[keep], rate[keep]
    turned = np.concatenate([[0.0], np.cumsum(0.5 * (turn[1:] + turn[:-1]) * np.diff(t))])
    course = np.unwrap(angle[keep])
    best, ratio = MIN_CORRELATION, None
    for window in RATIO_WINDOWS:
        span = int(np.clip(np.searchsorted(t, t[0] + window), 1, len(t) // 2))
        changed, integral = course[span:] - course[:-span], turned[span:] - turned[:-span]
        if np.std(changed) > 0 and np.std(integral) > 0:
            correlation = float(np.corrcoef(changed, integral)[0, 1])
            if correlation >= best:
                best, ratio = correlation, float(changed @ integral / (integral @ integral))
    return ratio


def angle_rate(angle: str, values: np.ndarray, rate: str, rates: np.ndarray, time: np.ndarray
               ) -> str:
    """Why a recorded ``angle`` (rad) and its ``rate`` (rad/s) disagree on the unit, or ``""``:
    the angle changes more than :data:`BEYOND_BOUND` times what the rate's integral says
    (degrees declared as rad?), or less than a :data:`BEYOND_BOUND`-th of it (deg/s declared as
    rad/s?) (:func:`angle_rate_ratio`)."""
    ratio = angle_rate_ratio(values, rates, time)
    if ratio is None or 1 / BEYOND_BOUND <= ratio <= BEYOND_BOUND:
        return ""
    if 1 / DEGREE_SLIP <= max(ratio, 1 / ratio) / 1000 <= DEGREE_SLIP:
        return (f"{angle} and its rate {rate} disagree by {max(ratio, 1 / ratio):.0f}x: the "
                "time in milliseconds (or seconds) declared as the other?")
    if ratio > BEYOND_BOUND:
        return (f"{angle}: turns {ratio:.0f}x more than the rate {rate} says: degrees declared "
                f"as rad (or {rate} in the wrong unit)?")
    return (f"{rate}: says {angle} turns {1 / ratio:.0f}x more than it does: deg/s declared as "
            f"rad/s (or {angle} in the wrong unit)?")


def degree_slip(ratio: float | None) -> bool:
    """Whether an :func:`angle_rate_ratio` is 180 / pi or its inverse (within
    :data:`DEGREE_SLIP`): one of the two is in degrees, beyond doubt."""
    if ratio is None or ratio <= 0:
        return False
    factor = max(ratio, 1 / ratio) * DEGREE
    return 1 / DEGREE_SLIP <= factor <= DEGREE_SLIP


def _unit_hint(si_unit: str, declared: str, peak: float, bound: float) -> str:
    """The likeliest unit mistake behind ``peak`` beyond ``bound`` (SI units)."""
    if declared == si_unit:
        # a unit whose conversion brings the peak to a tenth of the bound or more, within
        # it; the smallest change first
        fits = sorted((factor, unit) for unit, (si, factor) in UNIT_CONVERSIONS.items()
                      if si == si_unit and factor < 1
                      and 0.1 * bound <= peak * factor <= BEYOND_BOUND * bound)
        if fits:
            return f"{fits[-1][1].replace('deg', 'degrees')} declared as {declared}?"
    return "a unit mistake, or not the model's input?"


__all__ = ["PlausibilityWarning", "angle_rate", "angle_rate_ratio", "degree_slip",
           "environment_arguments", "rate_pairs", "recorded_values", "warn"]
