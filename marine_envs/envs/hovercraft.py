"""Hovercraft-v0: course keeping of an air-cushion vehicle at cruise speed, in wind (the
hovercraft EKF paper)."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any, Unpack

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..manoeuvres import ZigzagRudder
from ..models.hovercraft import HovercraftModel
from ..sea.processes import GaussMarkov
from .base import MarineEnv, vector_env
from .core import SensorOptions, Simulator, make_sensors, make_task, uniform_initial_state

DEG = math.pi / 180
#: Doppler/GNSS speed log and fibre-optic gyro [PROPOSED]: noise std per channel, SI units.
DEFAULT_SENSORS = {"noise_std": {"u": 0.05, "v": 0.05, "r": 0.1 * DEG, "psi": 0.2 * DEG},
                   "sensor_range": {"u": 40.0, "v": 20.0, "r": math.pi / 2}}  # full scales
#: Bryson's rule: 5 deg of heading, 1 m/s of speed, a quarter pitch, 10 deg of rudder.
DEFAULT_STATE_WEIGHTS = {"psi": 1 / (5 * DEG) ** 2, "u": 1.0}
DEFAULT_INPUT_WEIGHTS = {"sigma_1": 16.0, "sigma_2": 16.0, "delta": 1 / (10 * DEG) ** 2}


def parse_zigzag(zigzag: str | Sequence[float]) -> tuple[float, float]:
    """``"20/20"`` (degrees, the manoeuvre's usual name) or ``(A, B)`` in radians -> radians."""
    if isinstance(zigzag, str):
        match = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*/\s*(\d+(?:\.\d*)?)\s*", zigzag)
        if not match:
            raise ValueError(f"zigzag={zigzag!r} is invalid: 'A/B' in degrees, e.g. '20/20'")
        return float(match[1]) * DEG, float(match[2]) * DEG
    amplitude, switch = (float(v) for v in zigzag)
    return amplitude, switch


class ZigzagSimulator(Simulator):
    """The simulator running an open-loop zig-zag test: the propeller pitch stays at its trim for
    the cruise speed and the rudder follows the zig-zag law; the agent's actions are validated
    but not applied."""

    def __init__(self, *args: Any, amplitude: float, switch: float, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.amplitude, self.switch = amplitude, switch
        self._rudder = self.model.input_names.index("delta")
        self._heading = self.model.state_names.index("psi")

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        self.zigzag = ZigzagRudder(self.amplitude, self.switch, batch_size)

    def reset(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator],
              x0: ArrayLike | None = None) -> None:
        super().reset(idx, rngs, x0)
        self.zigzag.reset(idx, initial_heading=self.x[idx, self._heading])

    def apply(self, action: ArrayLike) -> None:
        super().apply(action)
        u = np.tile(self.model.u0, (self.batch_size, 1))
        u[:, self._rudder] = self.zigzag(self.x[:, self._heading])
        self.u = u


def make_hovercraft_simulator(
    *,
    dt: float = 0.1,
    params: Mapping[str, float] | None = None,
    course: float = 0.0,
    wind_speed: float = 5.0,
    wind_direction: float = 45 * DEG,
    wind_gust: float = 1.0,
    wind_time_constant: float = 20.0,
    zigzag: str | Sequence[float] | None = None,
    initial_spread: Mapping[str, float] | None = None,
    state_weights: Mapping[str, float] | None = None,
    input_weights: Mapping[str, float] | None = None,
    disturbance_seed: int | None = None,
    **sensor_options: Unpack[SensorOptions],
) -> Simulator:
    """The hovercraft simulator; the keyword arguments are those of :class:`HovercraftEnv`."""
    model = HovercraftModel().with_params(**(params or {}))
    sensors = make_sensors(("u", "v", "r", "psi"), DEFAULT_SENSORS, sensor_options, wrap=("psi",))
    if not math.isfinite(course):
        raise ValueError(f"course={course!r} is invalid: a finite heading in rad")
    task = make_task(model, DEFAULT_STATE_WEIGHTS if state_weights is None else state_weights,
                     DEFAULT_INPUT_WEIGHTS if input_weights is None else input_weights,
                     reference={"psi": course})
    for name, value in (("wind_speed", wind_speed), ("wind_gust", wind_gust),
                        ("wind_time_constant", wind_time_constant)):
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name}={value!r} is invalid: must be finite and >= 0")
    # the air moves TO the opposite of where the wind comes FROM
    mean = -wind_speed * np.array([math.cos(wind_direction), math.sin(wind_direction)])
    wind = GaussMarkov(mean, wind_gust, wind_time_constant, dt=dt)
    spread = {"psi": 20 * DEG, "u": 1.0} if initial_spread is None else initial_spread
    kwargs = dict(integrator="rk4", substeps=2, disturbance_seed=disturbance_seed)
    args = (model, sensors, task, wind, dt, uniform_initial_state(model, spread))
    if zigzag is None:
        return Simulator(*args, **kwargs)
    amplitude, switch = parse_zigzag(zigzag)
    return ZigzagSimulator(*args, amplitude=amplitude, switch=switch, **kwargs)


class HovercraftEnv(MarineEnv):
    """Course keeping of an LCAC-like hovercraft at cruise speed, in gusty wind.

    ## Description
    A 150 t air-cushion vehicle (the hovercraft EKF paper; the MMG-separated model of
    docs/models.md 5, all coefficients proposed) runs at 32 kn on two air propellers with air
    rudders in their slipstream. It has little hydrodynamic grip, so it drifts in turns and the
    wind pushes it around: hold the commanded course (and the speed) with the propeller pitch and
    the rudders. With ``zigzag="A/B"`` the environment instead runs the standard open-loop
    zig-zag manoeuvre (rudder to +A, reversed whenever the heading has changed by B), the test
    that the paper identifies the model from.

    ## Action Space
    ``Box(-1, 1, (3,), float32)``: port and starboard propeller pitch (-0.5 ... 1, mapped
    linearly) and the rudder angle (+-30 deg). Clipped beyond, flagged in
    ``info["action_clipped"]``. In zig-zag mode actions are checked but ignored.

    ## Observation Space
    ``Box((4,), float32)``: measured ``[u, v, r, psi]`` (m/s, m/s, rad/s, rad) with noise (std
    0.05 m/s, 0.05 m/s, 0.1 deg/s, 0.2 deg); heading wrapped to (-pi, pi].

    ## Rewards
    Minus the discrete-LQR stage cost: heading error (5 deg = one unit), speed error (1 m/s),
    pitch (0.25 = one unit each) and rudder (10 deg), relative to straight running at the cruise
    speed on the commanded course.

    ## Starting State
    Straight running at the cruise speed, speed +-1 m/s and heading +-20 deg off the course; or
    ``reset(options={"state": x0})`` with ``[u, v, r, north, east, psi]``.

    ## Episode End
    Never terminated; truncated after 1000 steps (100 s).

    ## Info
    ``state`` (true ``[u, v, r, north, east, psi]``), ``action_applied`` (pitch, pitch, rudder
    rad), ``action_clipped``, ``disturbance`` (wind velocity north/east, m/s, the direction the
    air moves to), ``measurement_mask``, ``time`` (s).

    ## Arguments
    * ``dt``: control period, s (0.1).
    * ``params``: model overrides by docs/models.md name, e.g. ``{"u_cruise": 12.0}`` (cruise
      speed, m/s) or ``{"N_Hr": -1e6}``.
    * ``course``: commanded heading, rad (0).
    * ``wind_speed`` (5 m/s), ``wind_direction`` (where it blows from, rad clockwise from north:
      pi/4), ``wind_gust`` (std, m/s: 1) and ``wind_time_constant`` (s: 20) of the Gauss-Markov
      gusts on each wind component; ``wind_speed=0, wind_gust=0`` for still air.
    * ``zigzag``: None, ``"A/B"`` in degrees (``"5/5"``, ``"15/15"``, ``"25/25"``, ...) or
      ``(A, B)`` in radians: run the open-loop zig-zag test instead of the agent's actions.
    * ``noise_std``, ``bias``, ``quantization``, ``sensor_range``, ``sample_period``, ``delay``,
      ``dropout``: per channel (``u``, ``v``, ``r``, ``psi``), a number or ``{channel: value}``;
      None turns the stage off (:class:`~marine_envs.envs.core.SensorOptions`).
    * ``initial_spread``: ``{state: half-width}`` of the uniform initial state.
    * ``state_weights``, ``input_weights``: ``{name: weight}`` of the task cost.
    * ``disturbance_seed``: if set, every episode sees the same wind.
    """

    make_simulator = staticmethod(make_hovercraft_simulator)


HovercraftVectorEnv = vector_env(HovercraftEnv)
