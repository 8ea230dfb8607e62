"""Diagnosis cases drawn fresh from a seed: vehicle, effect and its size, sea, sensors, record
length and how the record was made.

:func:`draw` turns a seed into a :class:`Scenario` (frozen, JSON-able: :meth:`Scenario.to_dict`)
and :func:`record` makes its recording; both are fully determined by the seed, so a case drawn
on one machine is the same case on any other (a Ray worker, a later replay with ``--seeds``)::

    scenario = draw(1234)
    recording, truth = record(scenario)
    outcome = run_scenario(scenario)          # diagnosed and scored (``cases.score``)

A draw picks a vehicle (all five), one of four generators, a record length of 120-600 s, sensor
noise 1-3 times the default, the sea, a trial manoeuvre, and in :data:`PARTIAL_SHARE` of draws
only the channels of :data:`cases.PARTIAL` (the model stays observable). Then, in
:data:`EFFECT_FREE_SHARE` of draws, no effect; otherwise one catalogue entry of
:data:`cases.TARGETS` the generator can hide, sized by ``typical_effect`` at a random strength
and kept only if it changes the motion by at least :data:`MIN_CHANGE` RMS (both records
simulated, noise-free; the size is redrawn otherwise). The generators:

* ``environment``: the Gymnasium environment with ``effects=`` (its own sea, wind or current,
  sensors with their noise times the draw's factor, integrator), under the LQR autopilot of its
  task weights (the design ``synthesize`` uses) on the true state (an ideal observer; the DP
  vessel's sensors hold no low-frequency position) plus a trial manoeuvre: course changes, a
  zigzag of the set-point, set-point ramps, or holding course, with or without a random-step
  dither. The inputs recorded are the commands this loop sends, but ``marine simulate`` records
  the applied input, in which an actuator effect has already acted: unless the environment
  reports ``info["action_commanded"]``, only state effects (the time-invariant ones an
  environment takes) and sensor biases are drawn;
* ``synthesize``: :func:`.synthetic.synthesize`, the diagnosis's own generator (sensor noise
  5 % of each channel's spread times the draw's factor, as for the next two);
* ``open_loop``: the nonlinear model plus effects under random-step (PRBS-like) inputs and no
  controller, on the vehicles whose linearisation is stable (not the hydrofoil or the ROV);
* ``independent``: written here, sharing no code with ``synthesize`` (only the sizes of its
  sea and set-points): an LQR of the model's own linearisation (scipy's hold and Riccati
  solver), set-point ramps, a multisine dither, a first-order filtered sea, fixed-step RK4 of
  the nonlinear model plus effects, and white sensor noise.

:func:`run_seed` is one benchmark case (``benchmarks/diagnosis_scenarios.py``): the draw, the
record, the diagnosis bounded to :data:`TIMEOUT` s of CPU time, and its score.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import importlib
import math
import signal
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.signal

from marine_envs.models import VehicleModel, get_model
from marine_envs.models.effects import (
    INPUT_EFFECTS,
    ActuatorStream,
    Effect,
    EffectModel,
    resonator,
)
from marine_envs.recording import Recording

from .cases import ACCEPTANCE_VEHICLES, PARTIAL, TARGETS, Case, Entry, Outcome, build_effect, score
from .residuals import displacements
from .result import Diagnosis
from .synthetic import DEFAULT_DITHER_SHARE, DITHER_SHARE, REFERENCE, SEA, _gain, synthesize

DEG = math.pi / 180
GENERATORS = ("environment", "synthesize", "open_loop", "independent")
VEHICLES = ACCEPTANCE_VEHICLES
ENV_IDS = {"usv": "marine_envs/USV-v0", "hydrofoil": "marine_envs/Hydrofoil-v0",
           "rov": "marine_envs/ROV-v0", "dp_vessel": "marine_envs/DPVessel-v0",
           "hovercraft": "marine_envs/Hovercraft-v0"}
#: Share of draws without any effect (the false-finding rate is measured on them).
EFFECT_FREE_SHARE = 0.25
#: An effect is kept only if it changes the noise-free recorded motion by at least this share
#: of a channel's spread (RMS of the difference over the channel's standard deviation, the
#: largest over the channels): the issue's "changes the motion >= 15 % RMS".
MIN_CHANGE = 0.15
#: Record length, s; sensor noise, times each generator's default; share of partial records.
DURATION_RANGE, NOISE_RANGE, PARTIAL_SHARE = (120.0, 600.0), (1.0, 3.0), 0.3
#: The effect's strength (``typical_effect``'s share of the disturbed quantity's spread) is
#: drawn log-uniform here, then grown (or shrunk after a divergence) by SIZE_STEP, at most
#: SIZE_ATTEMPTS times per catalogue entry before another entry is drawn.
STRENGTH_RANGE, SIZE_STEP, SIZE_ATTEMPTS, ENTRY_ATTEMPTS = (0.15, 0.6), 1.7, 4, 6
#: Settings redrawn when the effect-free record already loses the vehicle.
SETTING_ATTEMPTS = 10
#: Sensor noise of the model generators at x1: a share of each channel's spread (the
#: acceptance set's lower level).
BASE_NOISE = 0.05
#: Trial manoeuvres: set-point steps held 20-60 s, a zigzag of the set-point, ramps between
#: set-points, or holding course (the autopilot against the sea and the dither alone).
MANOEUVRES = ("course_changes", "zigzag", "ramps", "hold")
#: Commands that are no actuator's, recorded as disturbance columns (the ROV's morph command).
COMMANDS: dict[str, tuple[str, ...]] = {"rov": ("s_cmd",)}
#: States the autopilot leaves alone: the ROV's morph state, which no input moves.
UNREGULATED: dict[str, tuple[str, ...]] = {"rov": ("s",)}
#: Sample (and control) period of the model generators, s: the environments' own.
SAMPLE_PERIOD = {"usv": 0.1, "hydrofoil": 0.05, "rov": 0.1, "dp_vessel": 0.5, "hovercraft": 0.1}
#: Open loop: the share of each input's half range its random steps span, held 1-6 s.
OPEN_LOOP_SHARE, OPEN_LOOP_HOLD = 0.3, (1.0, 6.0)
#: The independent generator: multisine dither (RMS share of each input's half range, the
#: hydrofoil's apart), its band, rad/s, and number of tones per input. The hydrofoil's flaps
#: stall beyond a little: at 0.032 its ramps diverged on 3 of 4 seeds (300 s), at 0.016 on
#: none of 3; below 0.2 rad/s the dither drifts it off its foils.
MULTISINE_SHARE, MULTISINE_BAND, MULTISINE_TONES = {"hydrofoil": 0.016}, (0.2, 2.0), 8
DEFAULT_MULTISINE_SHARE = 0.12
#: Catalogue entries an environment can hide (time-invariant state terms, sensor biases).
ENVIRONMENT_EFFECTS = ("current", "linear_damping", "quadratic_damping", "coupling",
                       "nonlinear_damping", "nonlinear_restoring", "unlisted", "sensor_bias")


@dataclass(frozen=True)
class Scenario:
    """One drawn case: everything :func:`record` needs, as plain data.

    :param seed: the draw's seed (also seeds the record: sea, manoeuvre, dither, sensors).
    :param vehicle: model name.  :param generator: one of :data:`GENERATORS`.
    :param effects: the concealed effects (none for an effect-free case).
    :param duration: record length, s.  :param noise: sensor noise, times the default.
    :param sea: generator settings of the sea (environment keyword arguments, or ``scale``).
    :param measured: the channels recorded (None: the generator's usual ones).
    :param manoeuvre: one of :data:`MANOEUVRES`.  :param dither: the dither's scale (0: none).
    :param change: the effect's RMS change of the motion (share of the spread), None without.
    :param strength: the ``typical_effect`` strength it was sized at, None without.
    """

    seed: int
    vehicle: str
    generator: str
    effects: tuple[Effect, ...] = ()
    duration: float = 300.0
    noise: float = 1.0
    sea: Mapping[str, Any] = field(default_factory=dict)
    measured: tuple[str, ...] | None = None
    manoeuvre: str = "course_changes"
    dither: float = 1.0
    change: float | None = None
    strength: float | None = None

    @property
    def name(self) -> str:
        """E.g. ``"environment/usv/quadratic_damping:r/seed=7"`` (``/partial`` when so)."""
        truth = "+".join(f"{e.effect}:{e.target}" for e in self.effects) or "none"
        partial = "/partial" if self.measured else ""
        return f"{self.generator}/{self.vehicle}/{truth}/seed={self.seed}{partial}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (effects as their ``to_dict``)."""
        out = dataclasses.asdict(self)
        out["effects"] = [e.to_dict() for e in self.effects]
        out["measured"] = None if self.measured is None else list(self.measured)
        out["sea"] = dict(self.sea)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Scenario:
        """The inverse of :meth:`to_dict`."""
        fields = dict(data)
        fields["effects"] = tuple(Effect(e["effect"], e["target"], e["parameters"])
                                  for e in fields.get("effects", ()))
        if fields.get("measured") is not None:
            fields["measured"] = tuple(fields["measured"])
        return cls(**fields)


# -- drawing --------------------------------------------------------------------------------------
def draw(seed: int, vehicles: Sequence[str] = VEHICLES,
         generators: Sequence[str] = GENERATORS) -> Scenario:
    """The scenario of ``seed`` (among ``vehicles`` and ``generators``, which filter the draw:
    the same seed with other filters is another case). Sizing an effect simulates the record
    with and without it (a few seconds per attempt).

    :raises ValueError: an unknown vehicle or generator, or no generator for the vehicles.
    """
    _check_names(vehicles, VEHICLES, "vehicle")
    _check_names(generators, GENERATORS, "generator")
    rng = np.random.default_rng([seed, 57])
    pairs = [(v, g) for v in vehicles for g in generators if _applies(g, v)]
    if not pairs:
        raise ValueError(f"no generator of {list(generators)} applies to {list(vehicles)} "
                         "(open loop needs an open-loop stable vehicle)")
    for _ in range(SETTING_ATTEMPTS):
        base = _draw_settings(seed, pairs, rng)
        try:
            nominal = _clean(base)
            break
        except FloatingPointError:  # these settings lose the vehicle without any effect
            continue
    else:
        raise RuntimeError(f"seed {seed}: {SETTING_ATTEMPTS} settings in a row lost the vehicle")
    if rng.random() < EFFECT_FREE_SHARE:
        return base
    vehicle, generator, duration = base.vehicle, base.generator, base.duration
    entries = effect_entries(vehicle, generator, base.measured)
    for _ in range(ENTRY_ATTEMPTS):
        entry = entries[rng.integers(len(entries))]
        strength = float(np.exp(rng.uniform(*np.log(STRENGTH_RANGE))))
        for _ in range(SIZE_ATTEMPTS):
            effect = _effect(vehicle, entry, strength, duration, rng)
            candidate = dataclasses.replace(base, effects=(effect,), strength=round(strength, 4))
            try:
                change = motion_change(nominal, _clean(candidate))
            except FloatingPointError:  # lost the vehicle: a smaller effect
                strength /= SIZE_STEP
                continue
            if change >= MIN_CHANGE:
                return dataclasses.replace(candidate, change=round(change, 4))
            strength *= SIZE_STEP
    raise RuntimeError(f"seed {seed}: no catalogue effect of {vehicle} under {generator} "
                       f"changed the motion by {MIN_CHANGE:.0%} in {ENTRY_ATTEMPTS} entries")


def _draw_settings(seed: int, pairs: Sequence[tuple[str, str]],
                   rng: np.random.Generator) -> Scenario:
    """Everything but the effect."""
    vehicle, generator = pairs[rng.integers(len(pairs))]
    return Scenario(seed=seed, vehicle=vehicle, generator=generator,
                    duration=float(round(rng.uniform(*DURATION_RANGE), -1)),
                    noise=round(float(rng.uniform(*NOISE_RANGE)), 2),
                    sea=_draw_sea(vehicle, generator, rng),
                    measured=_draw_channels(vehicle, generator, rng),
                    manoeuvre=MANOEUVRES[rng.integers(len(MANOEUVRES))],
                    dither=float(rng.choice([0.0, 1.0])) if generator == "environment" else 1.0)


def effect_entries(vehicle: str, generator: str,
                   measured: Sequence[str] | None = None) -> list[Entry]:
    """The :data:`cases.TARGETS` entries ``generator`` can hide on ``vehicle`` (recording
    ``measured``): an environment hides no parameter change or wave-frequency term (not
    time-invariant), nor an actuator effect if it reports only the applied input; a sensor
    bias needs its channel recorded; in open loop, a bias of a heading or position (which
    nothing holds) is the unknown initial value, so no sensor bias of a displacement."""
    entries = list(TARGETS[vehicle])
    channels = set(measured or _usual_channels(vehicle, generator))
    if generator == "environment":
        hidden = ENVIRONMENT_EFFECTS + (INPUT_EFFECTS if commands_recorded(vehicle) else ())
        entries = [e for e in entries if e[0] in hidden]
    entries = [e for e in entries if e[0] != "sensor_bias" or e[1] in channels]
    if generator == "open_loop":
        model = get_model(vehicle)
        kinematic = {model.state_names[i] for i in displacements(model)}
        entries = [e for e in entries if not (e[0] == "sensor_bias" and e[1] in kinematic)]
    return entries


@functools.cache
def commands_recorded(vehicle: str) -> bool:
    """Whether the environment reports the commanded input (``info["action_commanded"]``)."""
    import gymnasium as gym

    import marine_envs  # noqa: F401  (registers the environments)

    env = gym.make(ENV_IDS[vehicle], disable_env_checker=True)
    _, info = env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    env.close()
    return "action_commanded" in info


def motion_change(nominal: np.ndarray, disturbed: np.ndarray) -> float:
    """The largest over channels of RMS(disturbed - nominal) / std(nominal) (noise-free)."""
    n = min(len(nominal), len(disturbed))
    spread = np.std(nominal[:n], axis=0) + 1e-12
    return float(np.max(np.sqrt(np.mean((disturbed[:n] - nominal[:n]) ** 2, axis=0)) / spread))


def _check_names(given: Sequence[str], known: Sequence[str], what: str) -> None:
    unknown = sorted(set(given) - set(known))
    if unknown or not given:
        raise ValueError(f"unknown {what}(s) {unknown or '(none given)'}; choose from "
                         f"{', '.join(known)}")


def _applies(generator: str, vehicle: str) -> bool:
    if generator != "open_loop":
        return True
    A, _, _ = get_model(vehicle).linearize()
    return bool(np.max(np.linalg.eigvals(A).real) <= 1e-9)


def _usual_channels(vehicle: str, generator: str) -> tuple[str, ...]:
    if generator == "environment":
        return _env_channels(vehicle)
    model = get_model(vehicle)
    return tuple(getattr(model, "measured_names", model.state_names))


def _draw_channels(vehicle: str, generator: str,
                   rng: np.random.Generator) -> tuple[str, ...] | None:
    if rng.random() >= PARTIAL_SHARE:
        return None
    usual = _usual_channels(vehicle, generator)
    partial = tuple(c for c in PARTIAL[vehicle] if c in usual)
    return partial if partial != usual else None


def _draw_sea(vehicle: str, generator: str, rng: np.random.Generator) -> dict[str, Any]:
    """The sea: the environment's own keyword arguments, or a scale of the model sea."""
    if generator != "environment":
        return {"scale": round(float(rng.uniform(0.5, 2.0)), 3)}
    if vehicle == "usv":
        return {"hs": round(float(rng.uniform(1.0, 3.5)), 2),
                "tp": round(float(rng.uniform(6.0, 11.0)), 2),
                "spectrum": str(rng.choice(["pm", "jonswap"])),
                "wave_heading": round(float(rng.uniform(0, 180)) * DEG, 4)}
    if vehicle == "hydrofoil":
        return {"hs": round(float(rng.uniform(0.05, 0.3)), 3),
                "wave_heading": round(float(rng.uniform(0, 180)) * DEG, 4)}
    if vehicle == "rov":
        speed, heading = float(rng.uniform(0.0, 0.3)), float(rng.uniform(0, 2 * math.pi))
        return {"current": [round(speed * math.cos(heading), 4),
                            round(speed * math.sin(heading), 4), 0.0],
                "current_std": round(float(rng.uniform(0.02, 0.08)), 3)}
    if vehicle == "hovercraft":
        return {"wind_speed": round(float(rng.uniform(0.0, 10.0)), 2),
                "wind_direction": round(float(rng.uniform(0, 360)) * DEG, 4),
                "wind_gust": round(float(rng.uniform(0.5, 2.0)), 2)}
    return {}  # the DP vessel's sea is its model's own (bias and wave-frequency processes)


def _effect(vehicle: str, entry: Entry, strength: float, duration: float,
            rng: np.random.Generator) -> Effect:
    """``build_effect`` at ``strength``; a parameter change at 30-70 % of the record."""
    effect, target, extra = entry
    if effect == "parameter_change":
        extra = {**extra, "time": float(round(rng.uniform(0.3, 0.7) * duration))}
    return build_effect(vehicle, (effect, target, extra), strength=round(strength, 4))


# -- recording ------------------------------------------------------------------------------------
@dataclass
class Made:
    """A generator's output: the recording and its noise-free recorded channels ``(T, n)``."""

    recording: Recording
    clean: np.ndarray


def record(scenario: Scenario) -> tuple[Recording, tuple[Effect, ...]]:
    """The scenario's recording and the truth (its effects).

    :raises FloatingPointError: the vehicle was lost (never for a drawn scenario)."""
    return _make(scenario).recording, scenario.effects


def _clean(scenario: Scenario) -> np.ndarray:
    return _make(scenario, noise=False).clean


def _make(scenario: Scenario, noise: bool = True) -> Made:
    maker = {"environment": _environment, "synthesize": _synthesize,
             "open_loop": _open_loop, "independent": _independent}[scenario.generator]
    return maker(scenario, noise)


def _env_channels(vehicle: str) -> tuple[str, ...]:
    import gymnasium as gym

    import marine_envs  # noqa: F401

    env = gym.make(ENV_IDS[vehicle], disable_env_checker=True)
    return env.unwrapped.system.channels


def _references(vehicle: VehicleModel, kind: str, steps: int, dt: float,
                rng: np.random.Generator) -> np.ndarray:
    """The set-point ``(steps, n_x)`` of a trial manoeuvre about the nominal state."""
    x_ref = np.tile(vehicle.x0, (steps, 1))
    for name, size in REFERENCE.get(vehicle.name, {}).items():
        i = vehicle.state_names.index(name)
        x_ref[:, i] += _profile(kind, size, steps, dt, rng)
    return x_ref


def _profile(kind: str, size: float, steps: int, dt: float,
             rng: np.random.Generator) -> np.ndarray:
    out = np.zeros(steps)
    if kind == "hold":
        return out
    if kind == "zigzag":
        half = int(rng.uniform(15, 40) / dt)
        sign = np.where((np.arange(steps) // half) % 2 == 0, 1.0, -1.0)
        return size * rng.uniform(0.5, 1.0) * sign
    k, level = 0, 0.0
    while k < steps:
        hold = int(rng.uniform(20, 60) / dt)
        target = size * rng.uniform(-1, 1)
        if kind == "ramps":  # to the new set-point over the whole hold
            out[k:k + hold] = np.linspace(level, target, hold)[:steps - k]
        else:
            out[k:k + hold] = target
        level, k = target, k + hold
    return out


def _random_steps(n: int, steps: int, dt: float, hold: tuple[float, float],
                  rng: np.random.Generator) -> np.ndarray:
    """Random levels in [-1, 1] held ``hold`` s, per column."""
    out = np.zeros((steps, n))
    for j in range(n):
        k = 0
        while k < steps:
            length = max(1, int(rng.uniform(*hold) / dt))
            out[k:k + length, j] = rng.uniform(-1, 1)
            k += length
    return out


def _environment(scenario: Scenario, noise: bool) -> Made:
    """The environment with the effects under its LQR autopilot (true state) and a manoeuvre;
    the commands recorded."""
    env, channels = _make_env(scenario, noise)
    system, model = env.unwrapped.system, get_model(scenario.vehicle)
    dt = system.dt
    steps = int(round(scenario.duration / dt)) + 1
    K = _gain(model, dt)
    rng = np.random.default_rng([scenario.seed, 1])
    x_ref = _references(model, scenario.manoeuvre, steps, dt, rng)
    low, high = model.u_bounds
    share = DITHER_SHARE.get(model.name, DEFAULT_DITHER_SHARE) * scenario.dither
    dither = _random_steps(len(low), steps, dt, (1.0, 4.0), rng) * share * (high - low) / 2
    free = [model.state_names.index(n) for n in UNREGULATED.get(model.name, ())]
    commands = COMMANDS.get(model.name, ())
    logged = [model.disturbance_names.index(c) for c in commands]
    times, inputs, seen, states, recorded = [], [], [], [], []
    obs, info = env.reset(seed=scenario.seed)
    for k in range(steps):
        x = np.asarray(info["state"], dtype=float)
        error = x - x_ref[k]
        error[free] = 0.0
        u = np.clip(model.u0 - K @ error + dither[k], low, high)
        action = np.clip(system.actuation.to_action(u), -1, 1).astype(np.float32)
        times.append(info["time"])
        seen.append(np.asarray(obs, dtype=float))
        states.append(x)
        obs, _, terminated, _, info = env.step(action)
        inputs.append(np.asarray(info.get("action_commanded", u), dtype=float))
        recorded.append(np.asarray(info["disturbance"], dtype=float)[logged])
        if terminated:
            raise FloatingPointError(f"the {model.name} left its limits at t={times[-1]:.1f} s")
    env.close()
    keep = list(scenario.measured or channels)
    y, d = np.array(seen), np.array(recorded).reshape(steps, len(logged))
    rec = Recording.from_arrays(
        model.name, np.array(times), np.array(inputs),
        {c: y[:, channels.index(c)] for c in keep},
        meta=_meta(scenario, "environment", env=ENV_IDS[model.name]),
        disturbances={c: d[:, j] for j, c in enumerate(commands)})
    return Made(rec, _outputs(model, np.array(states), keep, scenario.effects))


def _make_env(scenario: Scenario, noise: bool) -> tuple[Any, tuple[str, ...]]:
    """The scenario's environment (its sea, the effects, the sensors' noise times
    ``scenario.noise``, or no noise nor quantization) and its sensor channels."""
    import gymnasium as gym

    import marine_envs  # noqa: F401  (registers the environments)

    env_id = ENV_IDS[scenario.vehicle]
    default = importlib.import_module(f"marine_envs.envs.{scenario.vehicle}") \
        .DEFAULT_SENSORS["noise_std"]
    sea = {k: tuple(v) if isinstance(v, list) else v for k, v in scenario.sea.items()}
    channels = _env_channels(scenario.vehicle)
    scale = scenario.noise if noise else 0.0
    sensors: dict[str, Any] = {"noise_std": {
        c: scale * (default[c] if isinstance(default, Mapping) else default) for c in channels}}
    if not noise:
        sensors["quantization"] = None
    dt = gym.make(env_id, disable_env_checker=True, **sea).unwrapped.system.dt
    steps = int(round(scenario.duration / dt)) + 1
    env = gym.make(env_id, max_episode_steps=steps + 1, disable_env_checker=True,
                   effects=list(scenario.effects), **sea, **sensors)
    return env, channels


def _outputs(model: VehicleModel, states: np.ndarray, channels: Sequence[str],
             effects: Sequence[Effect]) -> np.ndarray:
    """Noise-free recorded channels of a state history, with any sensor bias."""
    outputs = model.output(states) if model.output_names != model.state_names else states
    outputs = outputs[:, [model.output_names.index(c) for c in channels]]
    return EffectModel(model, effects).measure(outputs, channels)


def _meta(scenario: Scenario, generator: str, **more: Any) -> dict[str, Any]:
    return {"generator": f"estimators.diagnosis.scenarios:{generator}",
            "scenario": scenario.to_dict(), **more}


def _synthesize(scenario: Scenario, noise: bool) -> Made:
    """:func:`.synthetic.synthesize` (its clean channels: the same call without noise)."""
    args = dict(duration=scenario.duration, seed=scenario.seed, measured=scenario.measured,
                sea=float(scenario.sea.get("scale", 1.0)), dither=scenario.dither,
                reference=0.0 if scenario.manoeuvre == "hold" else 1.0)
    clean = synthesize(scenario.vehicle, scenario.effects, noise=0.0, **args)
    if not noise:
        return Made(clean, clean.measurements)
    rec = synthesize(scenario.vehicle, scenario.effects, noise=BASE_NOISE * scenario.noise,
                     **args)
    rec.meta.update(_meta(scenario, "synthesize"))
    return Made(rec, clean.measurements)


# -- the model generators: open loop and the independent closed loop ------------------------------
def _open_loop(scenario: Scenario, noise: bool) -> Made:
    """Random-step inputs about the nominal input, no controller."""
    model = get_model(scenario.vehicle)
    rng = np.random.default_rng([scenario.seed, 3])
    dt = SAMPLE_PERIOD[scenario.vehicle]
    steps = int(round(scenario.duration / dt)) + 1
    low, high = model.u_bounds
    levels = _random_steps(len(low), steps, dt, OPEN_LOOP_HOLD, rng)
    commands = np.clip(model.u0 + levels * OPEN_LOOP_SHARE * (high - low) / 2, low, high)
    return _simulate(scenario, model, dt, rng, noise, commands=commands)


def _independent(scenario: Scenario, noise: bool) -> Made:
    """A continuous LQR on the linearisation, set-point ramps and a multisine dither."""
    model = get_model(scenario.vehicle)
    rng = np.random.default_rng([scenario.seed, 4])
    dt = SAMPLE_PERIOD[scenario.vehicle]
    steps = int(round(scenario.duration / dt)) + 1
    kind = "ramps" if scenario.manoeuvre != "hold" else "hold"
    x_ref = _references(model, kind, steps, dt, rng)
    low, high = model.u_bounds
    t = np.arange(steps) * dt
    tones = np.exp(rng.uniform(*np.log(MULTISINE_BAND), size=(MULTISINE_TONES, len(low))))
    phases = rng.uniform(0, 2 * math.pi, size=tones.shape)
    sines = np.sin(t[:, None, None] * tones[None] + phases[None]).sum(axis=1)
    share = MULTISINE_SHARE.get(model.name, DEFAULT_MULTISINE_SHARE) * scenario.dither
    dither = sines / np.sqrt(MULTISINE_TONES / 2) * share * (high - low) / 2
    K = _sampled_lqr(model, dt)
    free = [model.state_names.index(n) for n in UNREGULATED.get(model.name, ())]

    def control(k: int, x: np.ndarray) -> np.ndarray:
        error = x - x_ref[k]
        error[free] = 0.0
        return np.clip(model.u0 - K @ error + dither[k], low, high)

    return _simulate(scenario, model, dt, rng, noise, control=control)


def _sampled_lqr(model: VehicleModel, dt: float) -> np.ndarray:
    """The discrete LQR gain of the model's linearisation, held over ``dt`` (scipy's
    zero-order hold and Riccati solver), on its environment's task weights. States neither
    weighted nor coupled (positions nobody holds) are left out; a design scipy cannot solve
    (a marginal mode it cannot move) is made on a slightly discounted plant."""
    from marine_envs.envs import task_weights

    A, B, _ = model.linearize()
    q, r = task_weights(model.name)
    Q = np.diag([q.get(n, 0.0) for n in model.state_names])
    R = np.diag([r[n] for n in model.input_names])
    keep = np.flatnonzero((np.diag(Q) > 0) | np.any(A != 0, axis=0))
    sub = np.ix_(keep, keep)
    n = keep.size
    Ad, Bd, *_ = scipy.signal.cont2discrete((A[sub], B[keep], np.eye(n), 0.0), dt, "zoh")
    for discount in (1.0, 0.999, 0.99):
        a, b = math.sqrt(discount) * Ad, math.sqrt(discount) * Bd
        try:
            P = scipy.linalg.solve_discrete_are(a, b, Q[sub] + 1e-6 * np.eye(n), R)
            break
        except (np.linalg.LinAlgError, ValueError):
            continue
    else:
        raise ValueError(f"no LQR design for {model.name!r}")
    K = np.zeros((B.shape[1], A.shape[0]))
    K[:, keep] = np.linalg.solve(R + b.T @ P @ b, b.T @ P @ a)
    return K


def _sea(model: VehicleModel, steps: int, dt: float, scale: float,
         rng: np.random.Generator) -> np.ndarray:
    """First-order filtered white noise per disturbance channel, of the model sea's size."""
    std, tau = SEA.get(model.name, ((0.0,) * len(model.disturbance_names), 0.0))
    std = scale * np.asarray(std, dtype=float)
    white = rng.standard_normal((steps, std.size))
    if tau == 0.0:
        return white * std / math.sqrt(dt)
    a = math.exp(-dt / tau)
    out = np.zeros_like(white)
    for k in range(1, steps):
        out[k] = a * out[k - 1] + math.sqrt(1 - a * a) * white[k]
    return out * std


def _simulate(scenario: Scenario, model: VehicleModel, dt: float, rng: np.random.Generator,
              noise: bool, commands: np.ndarray | None = None, control: Any = None,
              substeps: int = 5) -> Made:
    """RK4 of the model plus effects under ``commands`` (open loop) or ``control(k, x)``."""
    steps = len(commands) if commands is not None else int(round(scenario.duration / dt)) + 1
    truth = EffectModel(model, scenario.effects)
    d = _sea(model, steps, dt, float(scenario.sea.get("scale", 1.0)), rng)
    forcing = {k: resonator(e.parameters["omega"], e.parameters["zeta"],
                            e.parameters.get("std", 1.0), steps, dt, rng)
               for k, e in enumerate(scenario.effects) if e.effect == "wave_frequency"}
    actuator = ActuatorStream(model, scenario.effects, dt)
    x = model.x0.copy()
    states = np.empty((steps, x.size))
    inputs = np.empty((steps, len(model.input_names)))
    h = dt / substeps
    for k in range(steps):
        states[k] = x
        u = commands[k] if commands is not None else control(k, x)
        inputs[k] = u
        applied = actuator.step(u)
        w = {e: f[k] for e, f in forcing.items()}
        for s in range(substeps):
            t = k * dt + s * h
            k1 = truth.rhs(x, applied, d[k], t, w)
            k2 = truth.rhs(x + h / 2 * k1, applied, d[k], t + h / 2, w)
            k3 = truth.rhs(x + h / 2 * k2, applied, d[k], t + h / 2, w)
            k4 = truth.rhs(x + h * k3, applied, d[k], t + h, w)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)) or np.max(np.abs(x)) > 1e7:
            raise FloatingPointError(f"the simulated {model.name} diverged at t={k * dt:.1f} s")
    channels = list(scenario.measured or getattr(model, "measured_names", model.state_names))
    clean = _outputs(model, states, channels, scenario.effects)
    scale = BASE_NOISE * scenario.noise if noise else 0.0
    measured = clean + scale * np.std(clean, axis=0) * rng.standard_normal(clean.shape)
    rec = Recording.from_arrays(model.name, np.arange(steps) * dt, inputs,
                                dict(zip(channels, measured.T, strict=True)),
                                meta=_meta(scenario, scenario.generator))
    return Made(rec, clean)


# -- diagnosing and scoring -----------------------------------------------------------------------
#: Per-case limit on the diagnosis's CPU time, s (the issue's target is 30 s for a 300-s
#: record; this only bounds a run).
TIMEOUT = 300.0


class Timeout(BaseException):  # noqa: N818  (not an Exception: run_case must not swallow it)
    """The diagnosis took longer than its limit."""


def run_scenario(scenario: Scenario, timeout: float | None = TIMEOUT) -> dict[str, Any]:
    """Record, diagnose and score ``scenario``: a JSON-ready row (the scenario, the
    :class:`~.cases.Outcome` fields, ``verdict`` and ``cpu_seconds``). The diagnosis is
    stopped after ``timeout`` s of this process's CPU time (verdict ``timeout``)."""
    from .api import diagnose

    recording, truth = record(scenario)  # before any CPU limit: only the diagnosis is bounded
    case = Case(scenario.vehicle, truth, scenario.noise, scenario.seed, scenario.duration,
                scenario.measured)
    start, cpu = time.perf_counter(), time.process_time()
    try:
        with _cpu_limit(timeout):
            diagnosis = diagnose(recording, scenario.vehicle)
        timed_out = False
    except Timeout:
        diagnosis, timed_out = Diagnosis(scenario.vehicle, None, f"timeout after {timeout} s "
                                         "of CPU"), True
    except Exception as exc:  # a benchmark goes on past one crash
        diagnosis, timed_out = Diagnosis(scenario.vehicle, None,
                                         f"crashed: {type(exc).__name__}: {exc}"), False
    outcome = score(case, diagnosis, time.perf_counter() - start)
    outcome = dataclasses.replace(outcome, case=scenario.name)
    return {"scenario": scenario.to_dict(), **dataclasses.asdict(outcome),
            "refused": diagnosis.mismatch is None and not timed_out
            and not diagnosis.reason.startswith("crashed"),
            "verdict": verdict(outcome, diagnosis, timed_out),
            "cpu_seconds": round(time.process_time() - cpu, 2)}


def verdict(outcome: Outcome, diagnosis: Diagnosis, timed_out: bool = False) -> str:
    """``right``, ``wrong``, ``missed``, ``refused``, ``timeout`` or ``crashed`` for a case
    with effects; ``clean``, ``false``, ``refused``, ``timeout`` or ``crashed`` without."""
    if timed_out:
        return "timeout"
    if diagnosis.mismatch is None:
        return "crashed" if diagnosis.reason.startswith("crashed") else "refused"
    if not outcome.true:
        return "false" if outcome.false_alarm else "clean"
    if outcome.ranked_right and outcome.parameter_ok:
        return "right"
    return "wrong" if outcome.found else "missed"


@contextlib.contextmanager
def _cpu_limit(seconds: float | None) -> Iterator[None]:
    """Raise :class:`Timeout` in the block after ``seconds`` of this process's CPU time
    (SIGPROF; in the main thread only, where signals are delivered; elsewhere no limit)."""
    if not seconds or threading.current_thread() is not threading.main_thread() \
            or not hasattr(signal, "setitimer"):
        yield
        return

    def expire(number: int, frame: Any) -> None:
        raise Timeout

    before = signal.signal(signal.SIGPROF, expire)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, before)


def run_seed(seed: int, vehicles: Sequence[str] = VEHICLES,
             generators: Sequence[str] = GENERATORS,
             timeout: float | None = TIMEOUT) -> dict[str, Any]:
    """:func:`draw` and :func:`run_scenario` with one BLAS thread: one benchmark case, the
    same row wherever it runs (a process pool, a Ray worker). A draw that fails gives a row
    of verdict ``draw failed`` with the reason."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        try:
            scenario = draw(seed, vehicles, generators)
        except (RuntimeError, FloatingPointError) as error:
            return {"seed": seed, "verdict": "draw failed", "reason": str(error)}
        return {"seed": seed, **run_scenario(scenario, timeout)}
