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
from typing import Any

import numpy as np

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
#: Heading -> its rate channel, compared by :func:`heading_rate`.
HEADING_RATES = {"psi": "r"}
#: Units of the scale arguments, for the messages.
_UNITS = {"dt": "s", "hs": "m", "wind_speed": "m/s", "wind_gust": "m/s", "current_std": "m/s"}
DEGREE = math.pi / 180


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
    # a heading may be unwrapped over many turns (a hovercraft spinning): see heading_rate
    if si_unit == "rad" and peak > TWO_PI and not name.startswith(HEADINGS):
        return (f"{name}: {peak:.3g} rad exceeds 2 pi: "
                f"{'degrees declared as rad' if declared == 'rad' else 'a unit mistake'}?")
    return ""


def heading_rate(heading: str, psi: np.ndarray, rate: str, r: np.ndarray, time: np.ndarray
                 ) -> str:
    """Why a recorded heading ``psi`` (rad) and its rate ``r`` (rad/s) disagree on the unit,
    or ``""``: the (unwrapped) heading regressed on the integral of the rate, where both are
    known, more than :data:`BEYOND_BOUND` times it (degrees declared as rad?). Integrating
    averages the sensors' noise out; a heading the rate does not explain says nothing."""
    keep = np.isfinite(psi) & np.isfinite(r)
    if keep.sum() < 10:
        return ""
    t, turn = time[keep], r[keep]
    turned = np.concatenate([[0.0], np.cumsum(0.5 * (turn[1:] + turn[:-1]) * np.diff(t))])
    course = np.unwrap(psi[keep])
    turned, course = turned - turned.mean(), course - course.mean()
    if not np.std(turned) > 0 or not np.std(course) > 0 \
            or np.corrcoef(course, turned)[0, 1] < 0.5:
        return ""
    gain = float(course @ turned / (turned @ turned))
    if gain <= BEYOND_BOUND:
        return ""
    return (f"{heading}: turns {gain:.0f}x more than the rate {rate} says: degrees declared "
            f"as rad (or {rate} in the wrong unit)?")


def _unit_hint(si_unit: str, declared: str, peak: float, bound: float) -> str:
    """The likeliest unit mistake behind ``peak`` beyond ``bound`` (SI units)."""
    from .recording import UNIT_CONVERSIONS  # here: recording imports this module

    if declared == si_unit:
        # a unit whose conversion brings the peak to a tenth of the bound or more, within
        # it; the smallest change first
        fits = sorted((factor, unit) for unit, (si, factor) in UNIT_CONVERSIONS.items()
                      if si == si_unit and factor < 1
                      and 0.1 * bound <= peak * factor <= BEYOND_BOUND * bound)
        if fits:
            return f"{fits[-1][1].replace('deg', 'degrees')} declared as {declared}?"
    return "a unit mistake, or not the model's input?"


__all__ = ["PlausibilityWarning", "environment_arguments", "heading_rate", "recorded_values",
           "warn"]
