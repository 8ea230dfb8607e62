"""A zig-zag's criteria and a turn's steady values read off a heading and rudder history, a
record or a prediction alike (:func:`read_zigzag`, :func:`read_turn`), so that the two compare
alike; the definitions are those of :mod:`marine_envs.manoeuvres`."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..models.base import FloatArray


class ZigzagMetrics:
    """What every zig-zag's criteria give in degrees, and the time to check yaw: a simulated
    test's (:class:`~marine_envs.manoeuvres.ZigzagResult`, per boat) and those read off a
    history (:class:`ZigzagCriteria`) alike."""

    #: Radians to degrees for the values the class holds (numpy's for a batch's arrays).
    _degrees = staticmethod(math.degrees)

    @property
    def first_overshoot_deg(self) -> Any:
        """First overshoot angle, deg."""
        return self._degrees(self.first_overshoot)

    @property
    def second_overshoot_deg(self) -> Any:
        """Second overshoot angle, deg."""
        return self._degrees(self.second_overshoot)

    @property
    def time_to_check_yaw(self) -> Any:
        """Time from the second execute to the first overshoot peak, s."""
        return self.first_peak_time - self.initial_turning_time


@dataclasses.dataclass(frozen=True)
class ZigzagCriteria(ZigzagMetrics):
    """A zig-zag's standard criteria read off a heading and rudder history (a record or a
    simulation alike: :func:`read_zigzag`), with the test's settings as the history shows them.
    Angles in rad, times in s from the first execute; criteria the history does not reach are NaN.
    """

    amplitude: float  #: rudder amplitude A about the rudder's centre, rad
    switch: float  #: heading change B at the rudder reversals (:func:`_switch`), rad
    centre: float  #: the rudder's centre between its two plateaus, rad (an offset if not 0)
    rudder_rate: float | None  #: rudder slope between plateaus, rad/s; None = in one sample
    first_direction: int  #: +1: the rudder went positive first, -1 negative
    turn_sign: int  #: +1: a positive rudder turned the heading positive, else -1
    start: int  #: sample of the first execute
    reversal_times: FloatArray  #: times of the 2nd, 3rd, ... executes, s
    initial_turning_time: float  #: s
    first_overshoot: float  #: rad
    second_overshoot: float  #: rad
    first_peak_time: float  #: s


def read_zigzag(time: ArrayLike, heading: ArrayLike, rudder: ArrayLike) -> ZigzagCriteria:
    """The criteria of a zig-zag (:mod:`marine_envs.manoeuvres`) read off its history: the same
    reading for a record and for a prediction, so that they compare alike.

    The rudder's plateaus (its 5th and 95th percentiles) give A and the centre; an execute is
    where the rudder leaves a plateau, found by running back from its crossing of the midpoint
    at the rudder's own slope (a held sample: exact for an instantaneous or a rate-limited
    rudder, as :func:`zigzag` moves it); B is the heading change at the reversals (:func:`_switch`).

    :param time: (T,) s, uniform.  :param heading: (T,) rad.  :param rudder: (T,) rad, each
        sample held until the next.
    :raises ValueError: histories of different lengths, or a rudder that does not zig-zag
        (fewer than two reversals: a step to a turn looks like one).
    """
    t, psi, delta = (np.asarray(a, dtype=float) for a in (time, heading, rudder))
    if not t.shape == psi.shape == delta.shape or t.ndim != 1 or t.size < 3:
        raise ValueError(f"time, heading and rudder must be 1-D of one length >= 3; got "
                         f"{t.shape}, {psi.shape}, {delta.shape}")
    low, high = np.percentile(delta, [5, 95])
    amplitude, centre = (high - low) / 2, (high + low) / 2
    side = np.where(delta > centre + amplitude / 2, 1, np.where(
        delta < centre - amplitude / 2, -1, 0))
    sided = np.flatnonzero(side)
    if amplitude <= 0 or sided.size == 0:
        raise ValueError("the rudder does not zig-zag: it holds one angle")
    changes = sided[1:][np.diff(side[sided]) != 0]  # first sample on a new side
    if changes.size < 2:  # the first overshoot needs the second execute and the third
        raise ValueError(f"the rudder does not zig-zag: it reverses {changes.size} time(s), "
                         "fewer than twice (a turn, not a zig-zag?)")
    dt = float(np.median(np.diff(t)))
    rate = _rudder_rate(delta, centre, amplitude, dt)
    first = int(sided[0])
    levels = [centre] + [centre - side[i] * amplitude for i in changes]  # the level it left
    executes = [_execute(t, delta, i, old, rate, dt)
                for i, old in zip([first, *changes], levels, strict=True)]
    start = executes[0]
    change = np.unwrap(psi) - psi[start]
    first_direction = int(side[first])
    s1 = float(np.sign(change[executes[1]]))
    switch = _switch(change, executes[1:])
    ends = [*executes[3:5], None, None]
    p1, i1 = _peak(change, executes[1], executes[2], s1)
    p2, _ = _peak(change, executes[2], ends[0], -s1)
    rel = t - t[start]
    return ZigzagCriteria(
        amplitude=float(amplitude), switch=switch, centre=float(centre),
        rudder_rate=None if rate * dt >= amplitude else rate, first_direction=first_direction,
        turn_sign=int(s1 * first_direction), start=start,
        reversal_times=rel[executes[1:]], initial_turning_time=float(rel[executes[1]]),
        first_overshoot=p1 - switch, second_overshoot=p2 - switch,
        first_peak_time=float(rel[i1]) if i1 >= 0 else math.nan)


def _switch(change: FloatArray, reversals: list[int]) -> float:
    """The heading check B of the reversals: between the largest |heading change| a sample
    before one (not yet B) and the smallest at one (B reached), the middle; their mean when the
    two disagree (a pilot who reversed late or early)."""
    if not reversals:
        return math.nan
    at = np.abs(change[reversals])
    before = np.abs(change[[max(i - 1, 0) for i in reversals]])
    low, high = float(before.max()), float(at.min())
    return (low + high) / 2 if low < high else float(at.mean())


def _rudder_rate(delta: FloatArray, centre: float, amplitude: float, dt: float) -> float:
    """The rudder's slope between its plateaus, rad/s: the median step over the samples that
    cross its middle band (a step of 2A when it moves in one sample)."""
    step = np.abs(np.diff(delta))
    middle = np.abs(delta - centre) < amplitude / 2
    moving = (middle[1:] | middle[:-1] | (np.sign(delta[1:] - centre)
                                         != np.sign(delta[:-1] - centre)))
    return float(np.median(step[moving]) / dt) if moving.any() else 2 * amplitude / dt


def _execute(t: FloatArray, delta: FloatArray, crossing: int, old: float, rate: float,
             dt: float) -> int:
    """The sample where the rudder left level ``old`` on its way to ``crossing`` (the first
    sample past the midpoint): back along the rudder's slope, then one held sample on."""
    back = abs(delta[crossing] - old) / rate
    return int(np.clip(round((t[crossing] - back - t[0]) / dt) + 1, 0, crossing))


@dataclasses.dataclass(frozen=True)
class TurnCriteria:
    """A turn read off its heading and rudder history (:func:`read_turn`)."""

    rudder: float  #: the steady rudder, rad (median over the last half)
    yaw_rate: float  #: steady turning rate, rad/s (heading slope over the last fifth)

    @property
    def yaw_rate_deg(self) -> float:
        """Steady turning rate, deg/s."""
        return math.degrees(self.yaw_rate)


def read_turn(time: ArrayLike, heading: ArrayLike, rudder: ArrayLike) -> TurnCriteria:
    """The steady rudder (median of the last half) and turning rate (least-squares slope of
    the unwrapped heading over the last fifth) of a turn, record or prediction alike.

    :raises ValueError: histories of different lengths or shorter than 10 samples."""
    t, psi, delta = (np.asarray(a, dtype=float) for a in (time, heading, rudder))
    if not t.shape == psi.shape == delta.shape or t.ndim != 1 or t.size < 10:
        raise ValueError(f"time, heading and rudder must be 1-D of one length >= 10; got "
                         f"{t.shape}, {psi.shape}, {delta.shape}")
    last = slice(-max(2, t.size // 5), None)
    slope = np.polyfit(t[last], np.unwrap(psi)[last], 1)[0]
    return TurnCriteria(float(np.median(delta[t.size // 2:])), float(slope))


def _item(values: FloatArray, i: int) -> float:
    return float(values[i]) if len(values) > i else math.nan


def _peak(change: FloatArray, start: int, end: int | None, sign: float) -> tuple[float, int]:
    """Largest ``sign * change`` in [start, end) and its index; NaN if it sits at the end of the
    run (the heading was still moving away, the peak not reached)."""
    seg = sign * change[start:end]
    if seg.size == 0:
        return math.nan, -1
    i = int(np.argmax(seg))
    if end is None and i == seg.size - 1:
        return math.nan, -1
    return float(seg[i]), start + i
