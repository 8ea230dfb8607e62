"""ROV-v0: velocity, depth and heading keeping of a morphing underwater robot (the
morphing-robot patent)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Literal, Unpack

import numpy as np

from ..models.rov import THRUSTER_ALLOCATION, THRUSTER_LIMITS, ROVModel
from ..sea.processes import GaussMarkov, Stacked, StepEvent
from .base import MarineEnv, vector_env
from .core import (
    Actuation,
    SensorOptions,
    Simulator,
    make_sensors,
    make_task,
    uniform_initial_state,
)

DEG = math.pi / 180
CHANNELS = ("u", "v", "w", "phi", "theta", "psi", "p", "q", "r", "z")
#: DVL (u, v, w), fibre-optic gyro (attitude and rates) and depth cell; noise [PROPOSED in
#: docs/models.md 3.5, depth 2 cm]; the DVL pings at 5 Hz, the others every control step (10 Hz).
DEFAULT_SENSORS = {
    "noise_std": {"u": 0.01, "v": 0.01, "w": 0.01, "phi": 0.05 * DEG, "theta": 0.05 * DEG,
                  "psi": 0.05 * DEG, "p": 0.01 * DEG, "q": 0.01 * DEG, "r": 0.01 * DEG,
                  "z": 0.02},
    "sample_period": {"u": 2, "v": 2, "w": 2},
    # full scales [PROPOSED]: DVL 5 m/s, gyro 90 deg and 90 deg/s, a 300 m depth cell
    "sensor_range": {"u": 5.0, "v": 5.0, "w": 5.0, "phi": math.pi / 2, "theta": math.pi / 2,
                     "p": math.pi / 2, "q": math.pi / 2, "r": math.pi / 2, "z": 300.0},
}
#: Bryson's rule: 0.1 m/s of velocity, 0.2 m of depth, 5 deg of heading, 10 deg of roll and
#: pitch; the thrusters' ranges for the inputs.
DEFAULT_STATE_WEIGHTS = {"u": 100.0, "v": 100.0, "w": 100.0, "z": 25.0, "psi": 1 / (5 * DEG) ** 2,
                         "phi": 1 / (10 * DEG) ** 2, "theta": 1 / (10 * DEG) ** 2}
DEFAULT_INPUT_WEIGHTS = {"X": 1 / 30**2, "Y": 1 / 20**2, "Z": 1 / 20**2, "K": 1.0,
                         "M": 1 / 18.75**2, "N": 1 / 13.5**2}


def _actuation(model: ROVModel, mode: str) -> Actuation | None:
    if mode == "forces":
        return None
    if mode == "thrusters":
        return Actuation(tuple(f"f{i}" for i in range(1, 7)), *THRUSTER_LIMITS,
                         matrix=THRUSTER_ALLOCATION)
    raise ValueError(f"actuation={mode!r} is invalid: 'forces' or 'thrusters'")


def make_rov_simulator(
    *,
    dt: float = 0.1,
    params: Mapping[str, float] | None = None,
    actuation: Literal["forces", "thrusters"] = "forces",
    reference: Mapping[str, float] | None = None,
    current: tuple[float, float, float] = (0.1, 0.0, 0.0),
    current_std: float = 0.05,
    current_time_constant: float = 120.0,
    morph_time: float | None = None,
    morph_window: tuple[float, float] | None = (20.0, 80.0),
    initial_spread: Mapping[str, float] | None = None,
    state_weights: Mapping[str, float] | None = None,
    input_weights: Mapping[str, float] | None = None,
    substeps: int = 2,
    disturbance_seed: int | None = None,
    **sensor_options: Unpack[SensorOptions],
) -> Simulator:
    """The ROV simulator; the keyword arguments are those of :class:`ROVEnv` (see there)."""
    model = ROVModel().with_params(**(params or {}))
    sensors = make_sensors(CHANNELS, DEFAULT_SENSORS, sensor_options, wrap=("psi",))
    task = make_task(model, DEFAULT_STATE_WEIGHTS if state_weights is None else state_weights,
                     DEFAULT_INPUT_WEIGHTS if input_weights is None else input_weights,
                     reference=reference,
                     limits={"z": (0.0, 100.0), "phi": 60 * DEG, "theta": 60 * DEG})
    flow = GaussMarkov(current, current_std * np.array([1.0, 1.0, 0.2]), current_time_constant,
                       dt=dt)
    if morph_time is None and morph_window is None:
        morph = StepEvent([0.0], [0.0], dt=dt, time=0.0)  # no morph: cruise shape throughout
    else:
        morph = StepEvent([0.0], [1.0], dt=dt, time=morph_time,
                          window=None if morph_time is not None else morph_window)
    spread = {"u": 0.3, "v": 0.1, "z": 1.0, "psi": 20 * DEG} if initial_spread is None \
        else initial_spread
    return Simulator(model, sensors, task, Stacked(flow, morph), dt,
                     uniform_initial_state(model, spread), integrator="rk4", substeps=substeps,
                     disturbance_seed=disturbance_seed, actuation=_actuation(model, actuation))


class ROVEnv(MarineEnv):
    """Velocity, depth and heading keeping of a morphing underwater robot, in a current.

    ## Description
    A REMUS-100-sized robot (the morphing-robot patent; Prestero's 6-DOF model with six tunnel
    and stern thrusters, docs/models.md 3) cruises at a commanded body velocity, depth and heading
    through a slowly varying ocean current. Once per episode it morphs from the streamlined
    cruise shape to the work shape (manipulator deployed at the bow): axial drag grows ninefold,
    roll drag a hundred-and-sixtyfold, yaw and pitch crossflow moments change sign or triple, and
    the centre of gravity moves forward, so a controller tuned for cruise meets different physics.

    ## Action Space
    ``Box(-1, 1, (6,), float32)``. With ``actuation="forces"`` (default): generalised forces
    ``[X, Y, Z, K, M, N]`` over X -40...60 N, Y +-20 N, Z +-50 N, K +-1 N m (an idealised roll
    actuator), M +-18.75 N m, N +-13.5 N m. With ``actuation="thrusters"``: the six thruster
    forces over their limits (stern -20...30 N, lateral tunnels +-10 N, vertical tunnels +-25 N),
    mapped by the allocation matrix B_T (no roll authority). Clipped beyond, flagged in
    ``info["action_clipped"]``.

    ## Observation Space
    ``Box((10,), float32)``: DVL ``u, v, w`` (m/s, std 0.01, sampled at 5 Hz and held), gyro
    ``phi, theta, psi`` (rad, std 0.05 deg; heading wrapped) and ``p, q, r`` (rad/s, std
    0.01 deg/s), depth ``z`` (m, std 0.02). ``info["measurement_mask"]`` marks fresh samples.

    ## Rewards
    Minus the discrete-LQR stage cost about the reference (cruise at 1.5 m/s, 5 m depth, heading
    north): 0.1 m/s of velocity, 0.2 m of depth, 5 deg of heading, 10 deg of roll or pitch and the
    actuator ranges each give one unit.

    ## Starting State
    The reference with speed +-0.3 m/s, sway +-0.1 m/s, depth +-1 m and heading +-20 deg, cruise
    shape; or ``reset(options={"state": x0})`` with all 13 states.

    ## Episode End
    Terminated when the robot surfaces (z < 0), passes 100 m depth, or rolls or pitches beyond
    60 deg; truncated after 1000 steps (100 s).

    ## Info
    ``state`` (true ``[u, v, w, p, q, r, x, y, z, phi, theta, psi, s]``, s = morph fraction),
    ``action_applied`` (generalised forces, N and N m), ``action_clipped``, ``disturbance``
    (current north/east/down, m/s, and the morph command), ``measurement_mask``, ``time`` (s).

    ## Arguments
    * ``dt``: control period, s (0.1).
    * ``params``: model overrides by docs/models.md name (cruise values, e.g. ``{"Xuu": -2.0}``;
      ``work_<name>`` for the work shape; ``T_m``, the morph time constant, s).
    * ``actuation``: ``"forces"`` or ``"thrusters"``.
    * ``reference``: offsets from the nominal cruise state by state name, e.g.
      ``{"u": -0.5, "z": 5.0, "psi": 0.5}`` (m/s, m, rad).
    * ``current``: mean current (north, east, down), m/s (0.1, 0, 0); ``current_std``: std of its
      horizontal variation, m/s (0.05; a fifth of it vertically); ``current_time_constant``, s.
    * ``morph_time``: when the morph command comes, s; or None to draw it uniformly from
      ``morph_window`` (20-80 s); both None: no morph.
    * ``noise_std``, ``bias``, ``quantization``, ``sensor_range``, ``sample_period`` (control
      steps per sample), ``delay``, ``dropout``: per channel, a number or ``{channel: value}``;
      None turns the stage off (:class:`~marine_envs.envs.core.SensorOptions`).
    * ``initial_spread``: ``{state: half-width}`` of the uniform initial state.
    * ``state_weights``, ``input_weights``: ``{name: weight}`` of the task cost.
    * ``substeps``: RK4 steps per control period (2; 1 is about 1.7x faster, with errors of
      1e-4 m/s and 2e-3 rad/s against a fine solution under LQR).
    * ``disturbance_seed``: if set, every episode sees the same current and morph time.
    """

    make_simulator = staticmethod(make_rov_simulator)


ROVVectorEnv = vector_env(ROVEnv)
