"""DPVessel-v0: dynamic positioning of a supply vessel in waves (the DP wave-frequency
patent)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, Unpack

import numpy as np

from ..models.dp_vessel import DPVesselModel
from ..sea.processes import GaussMarkov
from .base import MarineEnv, vector_env
from .core import (
    InitialState,
    SensorOptions,
    Simulator,
    make_sensors,
    make_task,
    uniform_initial_state,
)

DEG = math.pi / 180
#: Position reference and gyrocompass: position sigma from the DP wave-frequency patent's
#: R_ident = 1e-3 m^2; the patent's 2e-2 on heading (8 deg if rad) is implausible, a gyrocompass's
#: 0.1 deg is used [PROPOSED].
DEFAULT_SENSORS = {"noise_std": {"north": math.sqrt(1e-3), "east": math.sqrt(1e-3),
                                 "psi": 0.1 * DEG},
                   "sensor_range": {"north": 1000.0, "east": 1000.0}}  # m, full scale
#: Bryson's rule: 1 m, 1 m and 1 deg of low-frequency error; 200 kN, 150 kN, 5 MN m of thrust.
DEFAULT_STATE_WEIGHTS = {"north_lf": 1.0, "east_lf": 1.0, "psi_lf": 1 / DEG**2}
DEFAULT_INPUT_WEIGHTS = {"X": 1 / 2e5**2, "Y": 1 / 1.5e5**2, "N": 1 / 5e6**2}
SETPOINT_STATES = {"north": "north_lf", "east": "east_lf", "psi": "psi_lf"}


def _stationary_initial_state(model: DPVesselModel, spread: Mapping[str, float],
                              setpoint: np.ndarray) -> InitialState:
    """LF position uniform around the set-point; bias and wave-frequency states drawn from their
    stationary distributions, so an episode starts in a developed sea and current."""
    p = model.params
    position = uniform_initial_state(model, spread, centre=setpoint)
    # stationary covariance of the WF filters: A P + P A' + E E' = 0
    from scipy.linalg import solve_continuous_lyapunov  # (here, not at import: 0.1 s)

    wave_cov = solve_continuous_lyapunov(p.A_w, -p.E_w @ p.E_w.T)
    # a square root by eigenvalues: a calm DOF (sigma_eta = 0) makes the covariance singular
    w, V = np.linalg.eigh((wave_cov + wave_cov.T) / 2)
    wave_root = V * np.sqrt(np.maximum(w, 0.0))
    return _StationaryInitialState(position, np.asarray(p.sigma_b, dtype=float), wave_root)


@dataclasses.dataclass(frozen=True, eq=False)
class _StationaryInitialState:
    """The LF position from ``position``; bias states of standard deviations ``bias_std``;
    wave-frequency states ``wave_root @ n`` with ``n`` standard normal."""

    position: InitialState
    bias_std: np.ndarray
    wave_root: np.ndarray

    def __call__(self, rng: np.random.Generator) -> np.ndarray:
        x = self.position(rng)
        x[6:9] = self.bias_std * rng.standard_normal(3)
        x[9:15] = self.wave_root @ rng.standard_normal(6)
        return x


def make_dp_simulator(
    *,
    dt: float = 0.5,
    params: Mapping[str, Any] | None = None,
    setpoint: Mapping[str, float] | None = None,
    initial_spread: Mapping[str, float] | None = None,
    state_weights: Mapping[str, float] | None = None,
    input_weights: Mapping[str, float] | None = None,
    max_offset: float = 50.0,
    disturbance_seed: int | None = None,
    **sensor_options: Unpack[SensorOptions],
) -> Simulator:
    """The DP simulator; the keyword arguments are those of :class:`DPVesselEnv` (see there)."""
    if not (math.isfinite(dt) and dt > 0):  # before the noise's 1/sqrt(dt) below
        raise ValueError(f"dt={dt!r} is invalid: the control period must be > 0 s")
    model = DPVesselModel().with_params(**(params or {}))
    sensors = make_sensors(DPVesselModel.measured_names, DEFAULT_SENSORS, sensor_options,
                           wrap=("psi",))
    if setpoint is not None and not isinstance(setpoint, Mapping):
        raise ValueError(f"setpoint={setpoint!r} is invalid: a mapping of north (m), east (m) "
                         'and psi (rad), e.g. {"north": 0, "east": 0, "psi": 3.1416}')
    unknown = sorted(set(setpoint or {}) - set(SETPOINT_STATES), key=str)
    if unknown:
        raise ValueError(f"setpoint: unknown key(s) {unknown}; known: north, east, psi")
    reference = {SETPOINT_STATES[k]: v for k, v in (setpoint or {}).items()}
    if not (math.isfinite(max_offset) and max_offset > 0):
        raise ValueError(f"max_offset={max_offset!r} is invalid: must be > 0 m")
    task = make_task(model, DEFAULT_STATE_WEIGHTS if state_weights is None else state_weights,
                     DEFAULT_INPUT_WEIGHTS if input_weights is None else input_weights,
                     reference=reference)
    # drive-off: the low-frequency position more than max_offset from the set-point
    for i in (0, 1):
        task.low[i], task.high[i] = task.x_ref[i] - max_offset, task.x_ref[i] + max_offset
    # unit-intensity white noise held over a step has standard deviation 1/sqrt(dt)
    noise = GaussMarkov(np.zeros(6), 1 / math.sqrt(dt), 0.0, dt=dt)
    spread = {"north_lf": 5.0, "east_lf": 5.0, "psi_lf": 5 * DEG} if initial_spread is None \
        else initial_spread
    # two RK4 steps per 0.5 s keep the wave-frequency oscillation's amplitude error per period
    # below 1e-5 (one step: 3e-4, a visible decay over an episode)
    initial_state = _stationary_initial_state(model, spread, task.x_ref)
    return Simulator(model, sensors, task, noise, dt, initial_state, integrator="rk4",
                     substeps=2, disturbance_seed=disturbance_seed)


class DPVesselEnv(MarineEnv):
    """Dynamic positioning: hold a supply vessel at a set-point against current and waves.

    ## Description
    The 76.2 m, 6000 t supply vessel of Fossen, Sagatun & Soerensen (1996) (docs/models.md 4)
    holds its position and heading with its thrusters. A slowly varying bias (current, wind and
    second-order wave drift; a Gauss-Markov process in the north-east frame) pushes it away; the
    first-order waves make it oscillate at wave frequency (one damped second-order filter per
    degree of freedom). The position reference and gyrocompass measure both motions plus noise
    (the DP wave-frequency patent): a good DP controller compensates the slow motion and leaves
    the wave-frequency motion alone, which needs a wave filter between the sensors and the
    controller.

    ## Action Space
    ``Box(-1, 1, (3,), float32)``: surge force, sway force and yaw moment, normalised by the
    thrust limits (600 kN, 400 kN, 15 MN m). Clipped beyond, flagged in ``info["action_clipped"]``.

    ## Observation Space
    ``Box((3,), float32)``: measured ``[north, east, psi]`` (m, m, rad) = low-frequency +
    wave-frequency motion + noise (std 0.032 m, 0.032 m, 0.1 deg; heading wrapped to (-pi, pi]).

    ## Rewards
    Minus the discrete-LQR stage cost of the low-frequency position error (1 m, 1 m, 1 deg give
    one unit each) and the thrust (200 kN, 150 kN, 5 MN m give one unit each). The wave-frequency
    motion is not penalised: thrusters cannot and should not follow it.

    ## Starting State
    Low-frequency position uniform within +-5 m, +-5 m, +-5 deg of the set-point at rest; bias and
    wave-frequency states drawn from their stationary distributions; or
    ``reset(options={"state": x0})`` with all 15 states.

    ## Episode End
    Terminated on a drive-off: the low-frequency position more than ``max_offset`` (50 m) from the
    set-point in north or east; truncated after 1000 steps (500 s).

    ## Info
    ``state`` (true 15 states: LF position, velocities, bias, WF states), ``action_applied``
    (N, N, N m), ``action_clipped``, ``disturbance`` (the six white-noise inputs),
    ``measurement_mask``, ``time`` (s).

    ## Arguments
    * ``dt``: control period, s (0.5, the DP wave-frequency patent's Ts).
    * ``params``: model parameter overrides (docs/models.md 4 names), e.g.
      ``{"w0": [0.8, 0.8, 0.8]}`` (wave-frequency peaks, rad/s), ``{"sigma_b": [1e5, 1e5, 2e6]}``
      (bias std, N, N, N m), ``{"sigma_eta": [2, 2, 0.05]}`` (WF motion RMS, m, m, rad),
      ``{"T_b": [500, 500, 500]}``.
    * ``setpoint``: ``{"north": m, "east": m, "psi": rad}`` (default the origin, heading north).
    * ``noise_std``, ``bias``, ``quantization``, ``sensor_range``, ``sample_period``, ``delay``,
      ``dropout``: per channel (``north``, ``east``, ``psi``), a number or ``{channel: value}``;
      None turns the stage off (:class:`~marine_envs.envs.core.SensorOptions`).
    * ``initial_spread``: ``{state: half-width}`` of the uniform initial LF state.
    * ``state_weights``, ``input_weights``: ``{name: weight}`` of the task cost.
    * ``max_offset``: drive-off distance, m (50).
    * ``disturbance_seed``: if set, every episode sees the same bias and wave history.
    """

    make_simulator = staticmethod(make_dp_simulator)


DPVesselVectorEnv = vector_env(DPVesselEnv)
