"""Standard manoeuvres: zig-zag and turning-circle tests on any vehicle model (no Gymnasium).

A model qualifies if it has a rudder input (``delta`` by default) and a heading state (``psi``);
the turning circle also needs the body velocities ``u``, ``v`` and the yaw rate ``r``. A ``speed``
argument needs the model to offer ``trim_point(speed) -> (x, u)`` (straight running at ``speed``).
Everything is in SI units and radians; the results also give the angles in degrees.

Zig-zag (ITTC 7.5-04-02-01, "Z-test" A/B): from steady straight running the rudder goes to +A
(starboard) at t = 0 (first execute). When the heading change from the initial heading reaches +B
the rudder goes to -A (second execute), when it reaches -B back to +A, and so on. The rudder moves
instantaneously by default (the ITTC test asks for the quickest rudder); a rate limit is optional.

Definitions used for the zig-zag metrics (times from the first execute, t = 0):

* initial turning time: time of the second execute (heading change first reaches +B);
* first (second) overshoot angle: how far the heading change goes past +B (-B) after the second
  (third) execute, i.e. ``max(psi - psi_0) - B`` (``-min(psi - psi_0) - B``);
* first peak heading ("maximum heading" in docs/models.md 5.3): ``B + first overshoot``, reached
  at the first peak time; time to check yaw = first peak time - initial turning time;
* period: time of one full cycle, from the second to the fourth execute.

:func:`read_zigzag` reads the same criteria (and A, B, the first direction, the rudder rate) off a
measured heading and rudder history, a record or a prediction alike; :func:`read_turn` a turn's
steady rudder and turning rate.

Turning circle: the rudder is held at ``delta`` from steady straight running. Steady values are
those at the end of the run: yaw rate r, drift angle ``beta = atan2(-v, u)`` (positive when the
velocity points out of a starboard turn, the beta of docs/models.md 5.2), speed
``U = hypot(u, v)`` and radius ``R = U/|r|``. Advance and transfer are read at a heading change
of 90 deg, the tactical diameter at 180 deg (transfer normal to the approach course).

Both are integrated by classical RK4 with the inputs held over each step (the rudder command is
updated at the start of a step), as in the checks of docs/models.md 5.3 (dt = 0.05 s).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .models.base import FloatArray, VehicleModel
from .models.integrate import rk4

#: Input names recognised as the rudder, state names recognised as the heading, in order.
RUDDER_NAMES = ("delta", "delta_r", "rudder")
HEADING_NAMES = ("psi",)


def wrap_angle(angle: ArrayLike) -> FloatArray:
    """Angle wrapped to [-pi, pi), rad."""
    return (np.asarray(angle, dtype=float) + np.pi) % (2 * np.pi) - np.pi


def _index(names: tuple[str, ...], wanted: tuple[str, ...], index: int | None, what: str,
           model: VehicleModel) -> int:
    if index is not None:
        if not 0 <= index < len(names):
            raise ValueError(f"{what}_index={index!r} is invalid: model {model.name!r} has "
                             f"{len(names)} ({', '.join(names)})")
        return index
    for name in wanted:
        if name in names:
            return names.index(name)
    raise ValueError(f"model {model.name!r} has no {what} ({' or '.join(wanted)}) among "
                     f"{', '.join(names)}; pass {what}_index")


class ZigzagRudder:
    """Vectorised zig-zag rudder state machine for a batch of boats (ITTC Z-test).

    Per boat it keeps the initial heading, the current rudder direction (+1 starboard, -1 port)
    and the number of rudder reversals. Call it each control step with the headings; it returns
    the rudder angles to apply (open loop, e.g. to override an agent's rudder action).

    :param amplitude: rudder amplitude A, rad (> 0); scalar or one per boat.
    :param switch: heading change B at which the rudder reverses, rad (> 0); scalar or per boat.
    :param batch_size: number of boats.
    :param first_direction: +1 (default, starboard first as ITTC) or -1 (port first).
    :param turn_sign: +1 (default) when a positive rudder turns the heading positive (SNAME
        convention, e.g. the hovercraft), -1 for models with the opposite sign (the USV).
    :param rudder_rate: rudder rate limit, rad/s; ``None`` (default) moves it instantaneously.
    :param rudder_index: position of the rudder in the input vector, for :meth:`apply`.
    :param heading_index: position of the heading in the state vector, for :meth:`apply`.
    """

    def __init__(self, amplitude: ArrayLike, switch: ArrayLike, batch_size: int = 1, *,
                 first_direction: int = 1, turn_sign: int = 1, rudder_rate: float | None = None,
                 rudder_index: int | None = None, heading_index: int | None = None) -> None:
        if not (isinstance(batch_size, (int, np.integer)) and batch_size >= 1):
            raise ValueError(f"batch_size={batch_size!r} is invalid: must be an integer >= 1")
        self.batch_size = int(batch_size)
        for name, value in (("amplitude", amplitude), ("switch", switch)):
            arr = np.asarray(value, dtype=float)
            if not (np.all(np.isfinite(arr)) and np.all(arr > 0)):
                raise ValueError(f"{name}={value!r} is invalid: must be finite and > 0 rad")
            try:
                arr = np.broadcast_to(arr, (self.batch_size,)).copy()
            except ValueError:
                raise ValueError(f"{name} has shape {arr.shape}; need a scalar or "
                                 f"({self.batch_size},)") from None
            setattr(self, name, arr)
        if first_direction not in (1, -1):
            raise ValueError(f"first_direction={first_direction!r} is invalid: +1 or -1")
        if turn_sign not in (1, -1):
            raise ValueError(f"turn_sign={turn_sign!r} is invalid: +1 or -1")
        if rudder_rate is not None and not (math.isfinite(rudder_rate) and rudder_rate > 0):
            raise ValueError(f"rudder_rate={rudder_rate!r} is invalid: must be > 0 rad/s or None")
        self.first_direction, self.turn_sign = first_direction, turn_sign
        self.rudder_rate = rudder_rate
        self.rudder_index, self.heading_index = rudder_index, heading_index
        self.initial_heading = np.zeros(self.batch_size)
        self.direction = np.full(self.batch_size, float(first_direction))
        self.reversals = np.zeros(self.batch_size, dtype=int)
        self.rudder = np.zeros(self.batch_size)
        self.reset()

    def reset(self, idx: Any = None, initial_heading: ArrayLike = 0.0,
              initial_rudder: ArrayLike = 0.0) -> None:
        """Start the test for boats ``idx`` (index, slice, mask or ``None`` = all).

        :param initial_heading: heading at the first execute, rad: a scalar, one per selected boat
            or one per boat of the batch.
        :param initial_rudder: rudder angle before the execute, rad; used only with a rate limit
            (without one the rudder is at ``first_direction * A`` at once).
        """
        sel = slice(None) if idx is None else idx
        heading = np.asarray(initial_heading, dtype=float)
        n_selected = self.initial_heading[sel].size
        if heading.shape == (self.batch_size,) and n_selected != self.batch_size:
            heading = heading[idx]  # one heading per boat of the whole batch: take the selected
        self.initial_heading[sel] = heading
        self.direction[sel] = self.first_direction
        self.reversals[sel] = 0
        if self.rudder_rate is None:
            self.rudder[sel] = self.first_direction * self.amplitude[sel]
        else:
            self.rudder[sel] = initial_rudder

    def heading_change(self, heading: ArrayLike) -> FloatArray:
        """Heading change from the initial heading, wrapped to [-pi, pi), rad."""
        return wrap_angle(np.asarray(heading, dtype=float) - self.initial_heading)

    def __call__(self, heading: ArrayLike, dt: float | None = None) -> FloatArray:
        """Rudder angle per boat, rad, for the current headings (rad, shape ``(batch_size,)``).

        :param dt: time since the previous call, s; needed only with a rudder rate limit.
        """
        change = self.heading_change(heading)
        # the rudder reverses once the heading has turned B the way the rudder drives it
        reverse = (self.turn_sign * self.direction) * change >= self.switch
        self.direction = np.where(reverse, -self.direction, self.direction)
        self.reversals += reverse
        target = self.direction * self.amplitude
        if self.rudder_rate is None:
            self.rudder = target
        else:
            if dt is None:
                raise ValueError("dt is needed with a rudder rate limit")
            step = self.rudder_rate * dt
            self.rudder = self.rudder + np.clip(target - self.rudder, -step, step)
        return self.rudder.copy()

    def apply(self, x: ArrayLike, u: ArrayLike, dt: float | None = None) -> FloatArray:
        """Inputs ``u`` (shape ``(batch_size, n_u)``) with the rudder column replaced by the
        zig-zag command for states ``x`` (shape ``(batch_size, n_x)``)."""
        if self.rudder_index is None or self.heading_index is None:
            raise ValueError("apply needs rudder_index and heading_index")
        u = np.array(u, dtype=float)
        u[..., self.rudder_index] = self(np.asarray(x)[..., self.heading_index], dt)
        return u


# -- simulation ---------------------------------------------------------------------------------
def _initial(model: VehicleModel, speed: ArrayLike | None, inputs: ArrayLike | None,
             n: int) -> tuple[FloatArray, FloatArray]:
    """Initial states (n, n_x) and inputs (n, n_u): the trim at ``speed`` or the nominal point."""
    if speed is None:
        x, u = np.tile(model.x0, (n, 1)), np.tile(model.u0, (n, 1))
    else:
        trim = getattr(model, "trim_point", None)
        if trim is None:
            raise TypeError(f"model {model.name!r} has no trim_point(speed); pass speed=None "
                            f"(nominal point) and inputs instead")
        points = [trim(float(s)) for s in np.broadcast_to(np.asarray(speed, float), (n,))]
        x = np.array([p[0] for p in points])
        u = np.array([p[1] for p in points])
    if inputs is not None:
        given = np.asarray(inputs, dtype=float)
        try:
            u = np.array(np.broadcast_to(given, u.shape))
        except ValueError:
            raise ValueError(f"inputs has shape {given.shape}; need ({u.shape[1]},) or "
                             f"{u.shape} ({', '.join(model.input_names)})") from None
    return x, u


def _disturbance(model: VehicleModel, disturbance: ArrayLike | None, n: int) -> FloatArray | None:
    if disturbance is None:
        return None
    n_d = len(model.disturbance_names)
    d = np.asarray(disturbance, dtype=float)
    try:
        d = np.broadcast_to(d, (n, n_d))
    except ValueError:
        raise ValueError(f"disturbance has shape {d.shape}; need ({n_d},) or ({n}, {n_d}) "
                         f"({', '.join(model.disturbance_names)})") from None
    if not np.all(np.isfinite(d)):
        raise ValueError(f"disturbance={disturbance!r} is invalid: must be finite")
    return d


def _simulate(model: VehicleModel, x: FloatArray, u: FloatArray, d: FloatArray | None,
              dt: float, steps: int, command: Callable[[FloatArray, float], FloatArray],
              rudder_index: int, stop: Callable[[], bool] | None = None
              ) -> tuple[FloatArray, FloatArray]:
    """RK4 with the inputs and disturbances held over each step; the rudder column is set by
    ``command(x, t)`` at the start of every step. Returns states (T, n, n_x) and rudder angles
    (T, n)."""
    states, rudders = [x], []
    for i in range(steps):
        u = u.copy()
        u[:, rudder_index] = command(x, i * dt)
        rudders.append(u[:, rudder_index])
        x = rk4(lambda z, _t, u=u: model.rhs(z, u, d), x, dt)
        if not np.isfinite(x).all():
            raise FloatingPointError(f"manoeuvre diverged at t={(i + 1) * dt:g} s")
        states.append(x)
        if stop is not None and stop():
            break
    rudders.append(rudders[-1])  # the last command is held to the end
    return np.array(states), np.array(rudders)


def _check_dt(dt: float, duration: float | None) -> None:
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt={dt!r} is invalid: must be > 0 s")
    if duration is not None and not (math.isfinite(duration) and duration >= dt):
        raise ValueError(f"duration={duration!r} is invalid: must be >= dt={dt} s")


def _batch(*values: ArrayLike | None) -> tuple[int, bool]:
    """Batch size of the broadcast arguments and whether they are all scalars."""
    arrays = [np.asarray(v, dtype=float) for v in values if v is not None]
    shape = np.broadcast_shapes(*(a.shape for a in arrays))
    if len(shape) > 1:
        raise ValueError(f"manoeuvre arguments must be scalars or 1-D, got shape {shape}")
    return (shape[0] if shape else 1), not shape


# -- zig-zag ------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ZigzagResult:
    """Time histories and metrics of a zig-zag test (definitions in the module docstring).

    Batch results (array arguments) have a boat axis after the time axis and per-boat metrics;
    scalar arguments give a single boat and float metrics. Angles in rad, times in s; metrics
    that the run was too short to reach are NaN.
    """

    amplitude: Any  #: rudder amplitude A, rad
    switch: Any  #: switching heading change B, rad
    time: FloatArray  #: (T,), s
    states: FloatArray  #: (T, [n,] n_x), model units
    rudder: FloatArray  #: (T, [n]), rad
    heading_change: FloatArray  #: (T, [n]) heading minus initial heading (unwrapped), rad
    reversal_times: Any  #: times of the 2nd, 3rd, ... executes, s (list of arrays for a batch)
    initial_turning_time: Any  #: s
    first_overshoot: Any  #: rad
    second_overshoot: Any  #: rad
    first_peak_time: Any  #: s
    max_heading: Any  #: largest |heading change| over the run, rad

    @property
    def first_overshoot_deg(self) -> Any:
        """First overshoot angle, deg."""
        return np.degrees(self.first_overshoot)

    @property
    def second_overshoot_deg(self) -> Any:
        """Second overshoot angle, deg."""
        return np.degrees(self.second_overshoot)

    @property
    def first_peak(self) -> Any:
        """Heading change at the first overshoot peak, B + first overshoot, rad (the "maximum
        heading" of docs/models.md 5.3)."""
        return self.switch + self.first_overshoot

    @property
    def first_peak_deg(self) -> Any:
        """First peak heading change, deg."""
        return np.degrees(self.first_peak)

    @property
    def max_heading_deg(self) -> Any:
        """Largest |heading change| over the run, deg."""
        return np.degrees(self.max_heading)

    @property
    def time_to_check_yaw(self) -> Any:
        """Time from the second execute to the first overshoot peak, s."""
        return self.first_peak_time - self.initial_turning_time

    @property
    def period(self) -> Any:
        """Time of one full cycle, from the second to the fourth execute, s."""
        if isinstance(self.reversal_times, list):
            return np.array([_item(t, 2) - _item(t, 0) for t in self.reversal_times])
        return _item(self.reversal_times, 2) - _item(self.reversal_times, 0)


@dataclasses.dataclass(frozen=True)
class ZigzagCriteria:
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

    @property
    def first_overshoot_deg(self) -> float:
        """First overshoot angle, deg."""
        return math.degrees(self.first_overshoot)

    @property
    def second_overshoot_deg(self) -> float:
        """Second overshoot angle, deg."""
        return math.degrees(self.second_overshoot)

    @property
    def time_to_check_yaw(self) -> float:
        """Time from the second execute to the first overshoot peak, s."""
        return self.first_peak_time - self.initial_turning_time


def read_zigzag(time: ArrayLike, heading: ArrayLike, rudder: ArrayLike) -> ZigzagCriteria:
    """The criteria of a zig-zag (module docstring) read off its history: the same reading for a
    record and for a prediction, so that they compare alike.

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


def zigzag(model: VehicleModel, amplitude: ArrayLike, switch: ArrayLike,
           speed: ArrayLike | None = None, duration: float | None = None, dt: float = 0.05,
           inputs: ArrayLike | None = None, *, first_direction: int = 1, turn_sign: int = 1,
           rudder_rate: float | None = None, rudder_index: int | None = None,
           heading_index: int | None = None, max_duration: float = 600.0,
           disturbance: ArrayLike | None = None) -> ZigzagResult:
    """Zig-zag test A/B of ``model`` by fixed-step RK4 (see the module docstring).

    :param model: any vehicle model with a rudder input and a heading state.
    :param amplitude: rudder amplitude A, rad; scalar or 1-D (a batch of tests).
    :param switch: heading change B that reverses the rudder, rad; scalar or 1-D.
    :param speed: approach speed, m/s (the model's ``trim_point``); ``None`` = nominal point.
    :param duration: run length, s; ``None`` runs until every boat has made three rudder
        reversals (enough for both overshoots and the period), at most ``max_duration``.
    :param dt: RK4 step, s.
    :param inputs: all inputs held during the test except the rudder (model units); default the
        trim inputs at ``speed``.
    :param first_direction: +1 starboard first (ITTC), -1 port first.
    :param turn_sign: +1 when a positive rudder turns the heading positive, else -1 (the
        overshoots are then measured the way the heading actually turns).
    :param rudder_rate: rudder rate limit, rad/s; ``None`` = instantaneous.
    :param rudder_index: input column of the rudder (default: found by name, ``delta``).
    :param heading_index: state column of the heading (default: ``psi``).
    :param max_duration: cap on the run length when ``duration`` is None, s.
    :param disturbance: constant disturbance, shape ``(n_d,)`` or ``(n, n_d)`` (model units,
        e.g. the hovercraft's wind); default zero.
    """
    _check_dt(dt, duration)
    _check_dt(dt, max_duration)
    i_rud = _index(model.input_names, RUDDER_NAMES, rudder_index, "rudder", model)
    i_psi = _index(model.state_names, HEADING_NAMES, heading_index, "heading", model)
    n, scalar = _batch(amplitude, switch, speed)
    x, u = _initial(model, speed, inputs, n)
    law = ZigzagRudder(amplitude, switch, n, first_direction=first_direction,
                       turn_sign=turn_sign, rudder_rate=rudder_rate)
    law.reset(initial_heading=x[:, i_psi], initial_rudder=u[:, i_rud])
    reversal_steps: list[FloatArray] = []

    def command(state: FloatArray, t: float) -> FloatArray:
        before = law.reversals.copy()
        rudder = law(state[:, i_psi], dt)
        reversal_steps.append(law.reversals > before)
        return rudder

    if duration is None:
        steps = int(math.ceil(max_duration / dt))
        stop = lambda: bool(np.all(law.reversals >= 3))  # noqa: E731
    else:
        steps, stop = int(round(duration / dt)), None
    d = _disturbance(model, disturbance, n)
    states, rudder = _simulate(model, x, u, d, dt, steps, command, i_rud, stop)
    time = np.arange(states.shape[0]) * dt
    change = np.unwrap(states[:, :, i_psi], axis=0) - states[0, :, i_psi]
    flips = np.array(reversal_steps)  # (T-1, n): True where a reversal was commanded

    metrics: dict[str, list] = {k: [] for k in ("reversal_times", "initial_turning_time",
                                                "first_overshoot", "second_overshoot",
                                                "first_peak_time")}
    for j in range(n):
        b = float(law.switch[j])
        steps_j = np.flatnonzero(flips[:, j])
        ends = list(steps_j[1:3]) + [None] * (3 - len(steps_j[1:3]))
        s1 = first_direction * turn_sign  # sign of the first heading change
        if steps_j.size:
            p1, i1 = _peak(change[:, j], int(steps_j[0]), ends[0], s1)
        else:
            p1, i1 = math.nan, -1
        if steps_j.size > 1:
            p2, _ = _peak(change[:, j], int(steps_j[1]), ends[1], -s1)
        else:
            p2 = math.nan
        metrics["reversal_times"].append(time[steps_j])
        metrics["initial_turning_time"].append(time[steps_j[0]] if steps_j.size else math.nan)
        metrics["first_overshoot"].append(p1 - b)
        metrics["second_overshoot"].append(p2 - b)
        metrics["first_peak_time"].append(time[i1] if i1 >= 0 else math.nan)
    max_heading = np.max(np.abs(change), axis=0)

    if scalar:
        return ZigzagResult(
            amplitude=float(law.amplitude[0]), switch=float(law.switch[0]), time=time,
            states=states[:, 0], rudder=rudder[:, 0], heading_change=change[:, 0],
            reversal_times=metrics.pop("reversal_times")[0], max_heading=float(max_heading[0]),
            **{k: float(v[0]) for k, v in metrics.items()})
    return ZigzagResult(
        amplitude=law.amplitude, switch=law.switch, time=time, states=states, rudder=rudder,
        heading_change=change, reversal_times=metrics.pop("reversal_times"),
        max_heading=max_heading, **{k: np.array(v) for k, v in metrics.items()})


# -- turning circle -----------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class TurningResult:
    """Time histories and steady values of a turning-circle test (module docstring).

    Batch results (array arguments) have a boat axis after the time axis; scalar arguments give
    float values. Angles in rad, speeds in m/s, lengths in m; unreached values are NaN.
    """

    rudder: Any  #: rudder angle held, rad
    time: FloatArray  #: (T,), s
    states: FloatArray  #: (T, [n,] n_x), model units
    track: FloatArray  #: (T, [n,] 2) north and east of the reference point, m
    yaw_rate: Any  #: steady yaw rate r, rad/s
    drift_angle: Any  #: steady drift angle beta = atan2(-v, u), rad
    speed: Any  #: steady speed U = hypot(u, v), m/s
    surge: Any  #: steady surge velocity u, m/s
    radius: Any  #: steady turning radius U/|r|, m
    advance: Any  #: advance at 90 deg heading change, m
    transfer: Any  #: transfer at 90 deg heading change, m
    tactical_diameter: Any  #: transfer at 180 deg heading change, m
    steady: Any  #: True when r changed by < 0.1 % over the last 10 % of the run

    @property
    def yaw_rate_deg(self) -> Any:
        """Steady yaw rate, deg/s."""
        return np.degrees(self.yaw_rate)

    @property
    def drift_angle_deg(self) -> Any:
        """Steady drift angle, deg."""
        return np.degrees(self.drift_angle)


def _at_heading(change: FloatArray, values: FloatArray, target: float) -> float:
    """``values`` interpolated where |heading change| first reaches ``target`` rad (else NaN)."""
    reached = np.flatnonzero(np.abs(change) >= target)
    if reached.size == 0 or reached[0] == 0:
        return math.nan
    i = reached[0]
    a, b = abs(change[i - 1]), abs(change[i])
    w = (target - a) / (b - a)
    return float(values[i - 1] + w * (values[i] - values[i - 1]))


def turning_circle(model: VehicleModel, rudder: ArrayLike, speed: ArrayLike | None = None,
                   duration: float = 300.0, dt: float = 0.05, inputs: ArrayLike | None = None,
                   *, rudder_index: int | None = None,
                   heading_index: int | None = None,
                   disturbance: ArrayLike | None = None) -> TurningResult:
    """Turning-circle test: the rudder held at ``rudder`` from steady straight running.

    :param model: a vehicle model with a rudder input and states ``u``, ``v``, ``r`` and ``psi``
        (positions ``north``/``east`` are used if present, else integrated from u, v, psi).
    :param rudder: rudder angle, rad (> 0 = starboard); scalar or 1-D (a batch of tests).
    :param speed: approach speed, m/s (the model's ``trim_point``); ``None`` = nominal point.
    :param duration: run length, s; long enough to reach the steady turn.
    :param dt: RK4 step, s.
    :param inputs: all inputs held during the test except the rudder (model units); default the
        trim inputs at ``speed``. E.g. full pitch for a turn at full power.
    :param rudder_index: input column of the rudder (default: found by name, ``delta``).
    :param heading_index: state column of the heading (default: ``psi``).
    :param disturbance: constant disturbance, shape ``(n_d,)`` or ``(n, n_d)`` (model units);
        default zero.
    """
    _check_dt(dt, duration)
    i_rud = _index(model.input_names, RUDDER_NAMES, rudder_index, "rudder", model)
    i_psi = _index(model.state_names, HEADING_NAMES, heading_index, "heading", model)
    names = model.state_names
    missing = [s for s in ("u", "v", "r") if s not in names]
    if missing:
        raise ValueError(f"model {model.name!r} lacks states {missing} for a turning circle")
    i_u, i_v, i_r = (names.index(s) for s in ("u", "v", "r"))
    n, scalar = _batch(rudder, speed)
    x, u = _initial(model, speed, inputs, n)
    delta = np.broadcast_to(np.asarray(rudder, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(delta)):
        raise ValueError(f"rudder={rudder!r} is invalid: must be finite (rad)")
    d = _disturbance(model, disturbance, n)
    states, _ = _simulate(model, x, u, d, dt, int(round(duration / dt)), lambda s, t: delta,
                          i_rud)
    time = np.arange(states.shape[0]) * dt
    psi = states[:, :, i_psi]
    if "north" in names and "east" in names:
        track = states[:, :, [names.index("north"), names.index("east")]]
    else:  # trapezoidal integration of the earth-fixed velocity
        vel_u, vel_v = states[:, :, i_u], states[:, :, i_v]
        vel = np.stack([vel_u * np.cos(psi) - vel_v * np.sin(psi),
                        vel_u * np.sin(psi) + vel_v * np.cos(psi)], axis=-1)
        track = np.concatenate([np.zeros((1, n, 2)),
                                np.cumsum(0.5 * dt * (vel[1:] + vel[:-1]), axis=0)])
    change = np.unwrap(psi, axis=0) - psi[0]
    # advance along, transfer across the approach course (starboard positive)
    c0, s0 = np.cos(psi[0]), np.sin(psi[0])
    rel = track - track[0]
    along = rel[..., 0] * c0 + rel[..., 1] * s0
    across = -rel[..., 0] * s0 + rel[..., 1] * c0
    end = states[-1]
    r_end = end[:, i_r]
    r_before = states[-1 - max(1, (states.shape[0] - 1) // 10), :, i_r]
    steady = np.abs(r_end - r_before) <= 1e-3 * np.maximum(np.abs(r_end), 1e-9)
    speed_end = np.hypot(end[:, i_u], end[:, i_v])
    with np.errstate(divide="ignore"):
        radius = np.where(r_end != 0, speed_end / np.abs(r_end), np.inf)
    values = dict(
        yaw_rate=r_end, drift_angle=np.arctan2(-end[:, i_v], end[:, i_u]), speed=speed_end,
        surge=end[:, i_u], radius=radius,
        advance=np.array([_at_heading(change[:, j], along[:, j], np.pi / 2) for j in range(n)]),
        transfer=np.array([_at_heading(change[:, j], np.abs(across[:, j]), np.pi / 2)
                           for j in range(n)]),
        tactical_diameter=np.array([_at_heading(change[:, j], np.abs(across[:, j]), np.pi)
                                    for j in range(n)]),
        steady=steady)
    if scalar:
        return TurningResult(rudder=float(delta[0]), time=time, states=states[:, 0],
                             track=track[:, 0],
                             **{k: (bool(v[0]) if k == "steady" else float(v[0]))
                                for k, v in values.items()})
    return TurningResult(rudder=delta, time=time, states=states, track=track, **values)
