"""The zig-zag and turning-circle tests run on a vehicle model by fixed-step RK4 with the inputs
held over each step (:func:`zigzag`, :func:`turning_circle`; definitions in
:mod:`marine_envs.manoeuvres`), batched over boats."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..models.base import FloatArray, VehicleModel
from ..models.integrate import rk4
from .reading import ZigzagMetrics, _item, _peak
from .rudder import HEADING_NAMES, RUDDER_NAMES, ZigzagRudder, _index


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


def _in_degrees(name: str, doc: str) -> property:
    """A read-only property: the angle (rad) or rate (rad/s) ``name`` in degrees, per boat."""
    return property(lambda self: np.degrees(getattr(self, name)), doc=doc)


@dataclasses.dataclass(frozen=True)
class ZigzagResult(ZigzagMetrics):
    """Time histories and metrics of a zig-zag test (definitions in
    :mod:`marine_envs.manoeuvres`).

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
    _degrees = staticmethod(np.degrees)

    @property
    def first_peak(self) -> Any:
        """Heading change at the first overshoot peak, B + first overshoot, rad (the "maximum
        heading" of docs/models.md 5.3)."""
        return self.switch + self.first_overshoot

    first_peak_deg = _in_degrees("first_peak", "First peak heading change, deg.")
    max_heading_deg = _in_degrees("max_heading", "Largest |heading change| over the run, deg.")

    @property
    def period(self) -> Any:
        """Time of one full cycle, from the second to the fourth execute, s."""
        if isinstance(self.reversal_times, list):
            return np.array([_item(t, 2) - _item(t, 0) for t in self.reversal_times])
        return _item(self.reversal_times, 2) - _item(self.reversal_times, 0)


def zigzag(model: VehicleModel, amplitude: ArrayLike, switch: ArrayLike,
           speed: ArrayLike | None = None, duration: float | None = None, dt: float = 0.05,
           inputs: ArrayLike | None = None, *, first_direction: int = 1, turn_sign: int = 1,
           rudder_rate: float | None = None, rudder_index: int | None = None,
           heading_index: int | None = None, max_duration: float = 600.0,
           disturbance: ArrayLike | None = None) -> ZigzagResult:
    """Zig-zag test A/B of ``model`` by fixed-step RK4 (see :mod:`marine_envs.manoeuvres`).

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


@dataclasses.dataclass(frozen=True)
class TurningResult:
    """Time histories and steady values of a turning-circle test
    (:mod:`marine_envs.manoeuvres`).

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

    yaw_rate_deg = _in_degrees("yaw_rate", "Steady yaw rate, deg/s.")
    drift_angle_deg = _in_degrees("drift_angle", "Steady drift angle, deg.")


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
