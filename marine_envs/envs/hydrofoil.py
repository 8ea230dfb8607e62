"""Hydrofoil-v0: heave and pitch keeping of a foil-borne craft in a random sea (the hydrofoil
AKF paper)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Literal, Unpack

from ..models.base import LinearizedModel
from ..models.hydrofoil import HydrofoilModel
from ..sea import SeaState, WaveRealisation, wave_coupling
from .base import MarineEnv, vector_env
from .core import SensorOptions, Simulator, make_sensors, make_task, uniform_initial_state

DEG = math.pi / 180
#: The hydrofoil AKF paper: C = I4 and measurement noise variance WR = 0.003 on every channel.
DEFAULT_SENSORS = {"noise_std": math.sqrt(0.003),
                   "sensor_range": {"xi": 5.0, "theta": math.pi / 2, "xi_dot": 5.0,
                                    "theta_dot": math.pi / 2}}  # full scales [PROPOSED]
#: The hydrofoil AKF paper's LQR weights Q = diag(0, 100, 0, 1000), R = I2, plus a small heave
#: weight: with none the weakly unstable heave drifts to broaching within minutes; larger ones feed
#: the 5.5 cm heave noise into the foils.
DEFAULT_STATE_WEIGHTS = {"xi": 0.1, "theta": 100.0, "theta_dot": 1000.0}
DEFAULT_INPUT_WEIGHTS = {"alpha_s1": 1.0, "alpha_s2": 1.0}
#: docs/models.md 2.5 [PROPOSED]: Hs (m) rising from 0.10 to 0.30 and falling to 0.15 over 600 s.
DEFAULT_HS_SCHEDULE = ((0.0, 0.10), (100.0, 0.10), (200.0, 0.30), (350.0, 0.30), (450.0, 0.15),
                       (600.0, 0.15))
EPISODE_STEPS = 12000  #: 600 s at the default 0.05 s: the whole schedule


def make_hydrofoil_simulator(
    *,
    dt: float = 0.05,
    params: Mapping[str, Any] | None = None,
    model: Literal["nonlinear", "linear"] = "nonlinear",
    hs: float | Sequence[Sequence[float]] = DEFAULT_HS_SCHEDULE,
    tp: float | None = None,
    wave_heading: float = 120 * DEG,
    n_wave_components: int = 100,
    waves: bool = True,
    rich_waves: bool = False,
    initial_spread: Mapping[str, float] | None = None,
    state_weights: Mapping[str, float] | None = None,
    input_weights: Mapping[str, float] | None = None,
    max_pitch: float = 15 * DEG,
    disturbance_seed: int | None = None,
    **sensor_options: Unpack[SensorOptions],
) -> Simulator:
    """The hydrofoil simulator; the keyword arguments are those of :class:`HydrofoilEnv`."""
    craft = HydrofoilModel().with_params(**(params or {}))
    if model not in ("nonlinear", "linear"):
        raise ValueError(f"model={model!r} is invalid: 'nonlinear' or 'linear'")
    vehicle = craft if model == "nonlinear" else LinearizedModel(craft)
    sensors = make_sensors(vehicle.state_names, DEFAULT_SENSORS, sensor_options)
    if not (math.isfinite(max_pitch) and max_pitch > 0):
        raise ValueError(f"max_pitch={max_pitch!r} is invalid: must be > 0 rad")
    # foils broach when the CG is about a strut length above the surface; the hull touches the
    # water when it is half a metre above it [PROPOSED]
    p = craft.params
    task = make_task(vehicle, DEFAULT_STATE_WEIGHTS if state_weights is None else state_weights,
                     DEFAULT_INPUT_WEIGHTS if input_weights is None else input_weights,
                     limits={"xi": (-0.95 * p.l, -0.5), "theta": max_pitch})
    realisation = WaveRealisation(
        SeaState(hs=hs, tp=tp), wave_coupling(craft, wave_heading, rich=rich_waves), dt=dt,
        speed=p.U, heading=wave_heading, n_components=n_wave_components) if waves else None
    spread = {"xi": 0.05, "theta": 1 * DEG} if initial_spread is None else initial_spread
    # two RK4 steps per 0.05 s resolve the fastest open-loop pole (-38.7 1/s) to 2 %
    integrator = "rk4" if model == "nonlinear" else "exact"
    return Simulator(vehicle, sensors, task, realisation, dt,
                     uniform_initial_state(vehicle, spread), integrator=integrator,
                     substeps=2, disturbance_seed=disturbance_seed)


class HydrofoilEnv(MarineEnv):
    """Heave and pitch keeping of a fully submerged two-foil craft, in a random sea.

    ## Description
    A 102 kg unmanned hydrofoil (the hydrofoil AKF paper; the quasi-steady two-foil model of
    docs/models.md 2) flies at 6.08 m/s with its hull 1.04 m above the water, carried by a front
    and a rear foil 2 m down on struts. Their angles are the controls. The waves' orbital
    velocities change the foils' angles of attack; heave is weakly unstable (a slow +0.17 1/s
    pole), so the craft must be flown. The sea is Pierson-Moskowitz with a significant wave
    height that changes over the episode, met at 120 deg (bow-quartering).

    ## Action Space
    ``Box(-1, 1, (2,), float32)``: front and rear foil angles over +-15 deg (trim 2.37 and
    1.05 deg). Clipped beyond, flagged in ``info["action_clipped"]``.

    ## Observation Space
    ``Box((4,), float32)``: ``[xi, theta, xi_dot, theta_dot]`` (m, down positive; rad; m/s;
    rad/s), C = I4, with the hydrofoil AKF paper's measurement noise of variance 0.003 on each
    channel (std 0.055: 3.1 deg on pitch, which dominates the pitch error of any filter-free
    controller).

    ## Rewards
    Minus the LQR stage cost: Q = diag(0.1, 100, 0, 1000) on the deviation from trim and R = I2
    on the foil angles' deviation from trim (rad): the hydrofoil AKF paper's weights plus a small
    heave weight, without which heave (weakly unstable) drifts to broaching; pass
    ``state_weights={"theta": 100, "theta_dot": 1000}`` for the paper's own.

    ## Starting State
    Trim (xi = -1.04 m, theta = 2 deg) with heave +-0.05 m and pitch +-1 deg; or
    ``reset(options={"state": x0})``.

    ## Episode End
    Terminated when the foils broach (xi < -1.9 m), the hull touches the water (xi > -0.5 m) or
    |pitch| exceeds ``max_pitch`` (15 deg); truncated after 12000 steps (600 s: the whole
    Hs schedule).

    ## Info
    ``state`` (true state), ``action_applied`` (foil angles, rad), ``action_clipped``,
    ``disturbance`` (``[zeta_dot_1, zeta_dot_2, eta_1, eta_2, u_w1, u_w2]``: upward orbital
    velocity, surface elevation and horizontal orbital velocity at each foil), ``measurement_mask``,
    ``time`` (s).

    ## Arguments
    * ``dt``: control period, s (0.05).
    * ``params``: model overrides by docs/models.md name, e.g. ``{"lift_slope": "helmbold"}``,
      ``{"added_mass": True}``, ``{"U": 7.0}``.
    * ``model``: ``"nonlinear"`` (docs/models.md 2.3, RK4) or ``"linear"`` (its linearisation at
      trim, docs/models.md 2.4, stepped exactly).
    * ``hs``: significant wave height, m, or ``(t, hs)`` points of a schedule (default: the 600 s
      schedule 0.10 -> 0.30 -> 0.15 m of docs/models.md 2.5); ``tp``: peak period, s (None:
      one-parameter PM).
    * ``wave_heading``: encounter angle, rad (120 deg); ``n_wave_components`` (100);
      ``waves`` (True; False = calm water); ``rich_waves``: also the surface elevation and the
      horizontal orbital velocity (the "richer truth model" of docs/models.md 2.4; default False:
      the paper's).
    * ``noise_std``, ``bias``, ``quantization``, ``sensor_range``, ``sample_period``, ``delay``,
      ``dropout``: per channel, a number or ``{channel: value}``; None turns the stage off
      (:class:`~marine_envs.envs.core.SensorOptions`).
    * ``initial_spread``: ``{state: half-width}``; ``state_weights``, ``input_weights``.
    * ``max_pitch``: pitch that ends the episode, rad.
    * ``disturbance_seed``: if set, every episode sees the same sea.
    """

    make_simulator = staticmethod(make_hydrofoil_simulator)


HydrofoilVectorEnv = vector_env(HydrofoilEnv, EPISODE_STEPS)
