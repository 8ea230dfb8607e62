"""USV-v0: rudder-roll-yaw course keeping with roll damping in waves (the USV observer
patent)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Literal, Unpack

from ..models import USVModel
from ..sea import MeasuredSpectrum, SeaState, WaveRealisation, wave_coupling
from .base import MarineEnv, vector_env
from .core import SensorOptions, Simulator, make_sensors, make_task, uniform_initial_state
from .rendering import USVRenderer

DEG = math.pi / 180
#: Sensor defaults per measured channel (SI): noise standard deviation and quantization step.
DEFAULT_NOISE = {"r": 0.1 * DEG, "psi": 0.2 * DEG, "p": 0.1 * DEG, "phi": 0.1 * DEG}
DEFAULT_QUANTIZATION = {"r": 0.05 * DEG, "psi": 0.1 * DEG, "p": 0.05 * DEG, "phi": 0.1 * DEG}
#: Full scale of the rate gyros (90 deg/s) and the roll inclinometer (90 deg); heading wraps.
DEFAULT_RANGE = {"r": math.pi / 2, "p": math.pi / 2, "phi": math.pi / 2}
DEFAULT_SENSORS = {"noise_std": DEFAULT_NOISE, "quantization": DEFAULT_QUANTIZATION,
                   "sensor_range": DEFAULT_RANGE}
#: Bryson's rule: weight = 1 / (acceptable size)^2 -> heading 3 deg, roll 2 deg, rudder 10 deg.
DEFAULT_STATE_WEIGHTS = {"psi": 1 / (3 * DEG) ** 2, "phi": 1 / (2 * DEG) ** 2}
DEFAULT_INPUT_WEIGHTS = {"delta": 1 / (10 * DEG) ** 2}


def make_usv_simulator(
    *,
    dt: float = 0.1,
    params: Mapping[str, float] | None = None,
    hs: float | Sequence[Sequence[float]] | None = 2.0,
    tp: float | None = 8.0,
    spectrum: Literal["pm", "jonswap"] | MeasuredSpectrum = "pm",
    gamma: float = 3.3,
    wave_heading: float = 60 * DEG,
    speed: float = 7.7,
    n_wave_components: int = 64,
    waves: bool = True,
    coupling: Mapping[str, float] | None = None,
    quantizer: Literal["static", "zooming"] = "static",
    zoom_k: float = 0.6,
    initial_spread: Mapping[str, float] | None = None,
    state_weights: Mapping[str, float] | None = None,
    input_weights: Mapping[str, float] | None = None,
    max_roll: float = 40 * DEG,
    disturbance_seed: int | None = None,
    **sensor_options: Unpack[SensorOptions],
) -> Simulator:
    """The USV simulator; the keyword arguments are those of :class:`USVEnv` (see there)."""
    model = USVModel().with_params(**(params or {}))
    sensors = make_sensors(
        USVModel.measured_names, DEFAULT_SENSORS, sensor_options,
        wrap=("psi",), quantizer=quantizer, zoom_k=zoom_k)
    if not (math.isfinite(max_roll) and max_roll > 0):
        raise ValueError(f"max_roll={max_roll!r} is invalid: must be > 0 rad")
    task = make_task(model, DEFAULT_STATE_WEIGHTS if state_weights is None else state_weights,
                     DEFAULT_INPUT_WEIGHTS if input_weights is None else input_weights,
                     limits={"phi": max_roll})
    sea = SeaState(hs=hs, tp=tp, spectrum=spectrum, gamma=gamma)
    realisation = WaveRealisation(
        sea, wave_coupling(model, wave_heading, **(coupling or {})), dt=dt, speed=speed,
        heading=wave_heading, n_components=n_wave_components) if waves else None
    initial_state = uniform_initial_state(
        model, {"psi": 10 * DEG, "phi": 3 * DEG} if initial_spread is None else initial_spread)
    return Simulator(model, sensors, task, realisation, dt, initial_state,
                     disturbance_seed=disturbance_seed)


class USVEnv(MarineEnv):
    """Rudder-roll-yaw course keeping with roll damping, in waves.

    ## Description
    An unmanned surface vessel (the USV observer patent; the Van Amerongen rudder-roll model of
    docs/models.md 1) holds its course in a random sea using its rudder only, while damping the
    roll the waves excite. The rudder turns the ship and, through the sway it induces, rolls it:
    the classic rudder-roll-stabilisation trade-off. The sway speed is not measured.

    ## Action Space
    ``Box(-1, 1, (1,), float32)``: rudder angle normalised by the rudder limit (35 deg).
    Out-of-range actions are clipped and flagged in ``info["action_clipped"]``; NaN/inf raise.

    ## Observation Space
    ``Box((4,), float32)``: the patent's measured channels ``[r, psi, p, phi]`` (rad/s, rad,
    rad/s, rad) after bias, Gaussian noise, heading wrapping to (-pi, pi], quantization, sensor
    full scale (90 deg/s gyros, 90 deg inclinometer), delay and dropout, as configured. Default
    noise std 0.1 deg/s, 0.2 deg, 0.1 deg/s, 0.1 deg; default quantization steps 0.05 deg/s,
    0.1 deg, 0.05 deg/s, 0.1 deg.

    ## Rewards
    Minus the discrete-LQR stage cost ``x_k'Q x_k + u_k'R u_k`` of the state and rudder at the
    start of the step, with Bryson weights (heading 3 deg, roll 2 deg, rudder 10 deg give one unit
    each), so an episode's return is minus its LQR cost. The heading in the cost is the true,
    unwrapped heading: a full turn is not free.

    ## Starting State
    Heading uniform in +-10 deg and roll in +-3 deg (``initial_spread``), other states zero; or
    ``reset(options={"state": x0})``. Each episode draws new wave phases from the episode seed.

    ## Episode End
    Terminated when |roll| exceeds ``max_roll`` (40 deg); truncated after 1000 steps (100 s).

    ## Info
    ``state`` (true [v, r, psi, p, phi]), ``action_applied`` (rudder, rad), ``action_clipped``,
    ``disturbance`` ([w_psi, w_phi], rad/s^2), ``measurement_mask`` (False = dropped, value held),
    ``time`` (s).

    ## Arguments
    * ``dt``: control period, s (0.1).
    * ``params``: model parameter overrides by docs/models.md symbol, e.g. ``{"wn": 0.7}``.
    * ``hs``: significant wave height, m (2.0), a list of ``(t, hs)`` points for a schedule, or
      None with a measured spectrum; ``tp``: peak period, s (8.0; None = one-parameter PM);
      ``spectrum``: "pm", "jonswap" or a ``MeasuredSpectrum``; ``gamma``: JONSWAP gamma.
    * ``wave_heading``: encounter angle, rad (pi/3: stern-quartering, pi = head seas);
      ``speed``: ship speed for the encounter frequency, m/s (7.7 = 15 kn);
      ``n_wave_components`` (64); ``waves`` (True; False = calm water);
      ``coupling``: options of :class:`~marine_envs.sea.USVWaveCoupling`.
    * ``noise_std``, ``bias``, ``quantization``, ``sensor_range`` (full scale),
      ``sample_period`` (control steps per sample), ``delay`` (samples), ``dropout``
      (probability):
      a number for every channel or ``{channel: value}``, SI units; None turns the stage off
      (:class:`~marine_envs.envs.core.SensorOptions`); ``quantizer``: "static" or "zooming"
      (the USV observer patent's relative law, rate ``zoom_k``).
    * ``initial_spread``: ``{state: half-width}`` of the uniform initial state.
    * ``state_weights``, ``input_weights``: ``{name: weight}`` of the task cost.
    * ``max_roll``: roll angle that ends the episode, rad.
    * ``disturbance_seed``: if set, every episode sees the same sea (noise still varies).
    * ``render_mode``: None or "rgb_array" (heading, roll and rudder drawn; works with RecordVideo).
    """

    make_simulator = staticmethod(make_usv_simulator)
    renderer = USVRenderer


USVVectorEnv = vector_env(USVEnv)
