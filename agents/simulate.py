"""``marine simulate``: record an episode of any environment in the recording format, in
memory (:func:`~agents.simulate.simulate`) or streamed to a file as it runs
(:func:`~agents.simulate.record`); under an excitation signal, LQR, or the commands of another
recording replayed (``replay=``, ``marine simulate --replay RECORD``: the recorded commands
through the environment's vessel, e.g. a diagnosed one, ``effects="diagnosis.json"``)."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import signal
import threading
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

import marine_envs  # noqa: F401  (registers the environments)
from marine_envs.envs import System
from marine_envs.recording import APPLIED, CHUNK_ROWS, Recording, stream_recording

from .policies import LQR_STATE, canonical, make_policy, names

#: The policies a recording may run (:mod:`agents.policies`): all but the one that sees the true
#: state, which a real experiment could not run.
POLICIES = tuple(name for name in names() if name != LQR_STATE)
#: Seeds the actuator position sensors' noise together with the run's seed: its own stream, so
#: that recording an actuator changes nothing else in the run.
ACTUATOR_NOISE_STREAM = 0x61637475
#: Which inputs get an actuator position sensor: their names, or True for every input.
ActuatorSensors = Sequence[str] | bool


@dataclasses.dataclass
class Recorded:
    """What :func:`record` wrote: ``steps`` rows of ``requested`` into ``path``."""

    path: Path
    model: str
    steps: int
    requested: int
    seconds: float
    #: Why the run stopped, a phrase (also in the recording's metadata as ``stopped``).
    stopped: str
    #: The signal (``signal.SIGINT`` or ``SIGTERM``) that stopped it, or None.
    signal: int | None
    input_names: tuple[str, ...]
    measured_names: tuple[str, ...]
    disturbance_names: tuple[str, ...]
    #: The inputs recorded by an actuator position sensor too (columns ``<input>_applied``).
    actuator_names: tuple[str, ...] = ()


class _Run:
    """One simulation of :func:`simulate` and :func:`record`: the environment and policy,
    checked before any step, and the rows of the recording step by step."""

    def __init__(self, env_id: str, steps: int | None, seed: int | None, policy: str,
                 env_kwargs: Mapping[str, Any] | None, disturbances: Sequence[str],
                 policy_options: Mapping[str, float], actuator_sensors: ActuatorSensors = (),
                 actuator_noise: float | Mapping[str, float] = 0.0,
                 replay: Recording | None = None) -> None:
        env_kwargs = dict(env_kwargs or {})
        if replay is not None:
            steps, env_kwargs = _replay_settings(replay, steps, policy_options, env_kwargs)
        if steps is None or steps < 2:
            raise ValueError(f"steps={steps!r} is invalid: a recording needs at least 2 steps")
        policy = canonical(policy)  # the recording names the policy by its one name
        if policy not in POLICIES:
            raise ValueError(f"unknown policy {policy!r}; choose from {', '.join(POLICIES)}")
        self.env = gym.make(env_id, max_episode_steps=steps, **env_kwargs)
        system = self.system = self.env.unwrapped.system
        names = system.model.disturbance_names
        unknown = sorted(set(disturbances) - set(names))
        if unknown:
            raise ValueError(f"unknown disturbance(s) {unknown} of {env_id}: choose from "
                             f"{', '.join(names) or 'none'}")
        inputs = system.model.input_names
        self.actuators = _actuators(actuator_sensors, inputs, env_id)
        self._noise = _actuator_noise(actuator_noise, self.actuators)
        self._applied = [inputs.index(name) for name in self.actuators]
        self._rng = np.random.default_rng(None if seed is None else
                                          [ACTUATOR_NOISE_STREAM, seed])
        self.reset_options: dict[str, Any] | None = None
        if replay is None:
            self.policy = make_policy(policy, self.env, seed, **policy_options)
        else:
            self.policy = _replaying(replay, env_id, system)
            self.reset_options = {"state": release_state(replay, system.model)}
            policy = "replay"
        self.steps, self.seed = steps, seed
        self._recorded = [names.index(name) for name in disturbances]
        self.columns = ["time", *inputs, *(name + APPLIED for name in self.actuators),
                        *disturbances, *system.channels]
        self.params = dataclasses.asdict(system.model.params)
        self.meta = {"env": env_id, "seed": seed, "policy": policy,
                     "policy_options": dict(policy_options), "dt": system.dt,
                     "env_kwargs": env_kwargs, "steps_requested": steps}
        if self.actuators:
            self.meta["actuator_noise"] = dict(zip(self.actuators, self._noise.tolist(),
                                                   strict=True))
        self.terminated = False
        self.stopped = "not started"

    def rows(self, progress: bool = False) -> Iterator[np.ndarray]:
        """Each step's row (time, commanded inputs, actuator positions, recorded
        disturbances, sensor outputs: what the policy saw before it acted), until the episode
        ends; :attr:`stopped` then says why (a consumer that stops early says so itself)."""
        env = self.env
        obs, info = env.reset(seed=self.seed, options=self.reset_options)
        with _bar(self.steps, progress) as bar:
            for k in range(self.steps):
                # SB3's convention: episode_start resets a stateful policy (LQR's integrators)
                action, _ = self.policy.predict(obs, episode_start=np.array([k == 0]),
                                                deterministic=True)
                seen, time = obs, info["time"]
                obs, _, terminated, truncated, info = env.step(action)
                if bar is not None:
                    bar.update()
                yield np.concatenate(([time], info["action_commanded"],
                                      self._positions(info["action_applied"]),
                                      info["disturbance"][self._recorded], seen))
                if terminated:
                    self.terminated = True
                    self.stopped = (f"the episode terminated at step {k + 1} of {self.steps}: "
                                    f"{why_terminated(self.system, info['state'])}")
                    return
                if truncated and k + 1 < self.steps:
                    self.stopped = (f"the environment truncated the episode at step {k + 1} "
                                    f"of {self.steps}")
                    return
        self.stopped = f"the requested {self.steps} steps were reached"

    def _positions(self, applied: np.ndarray) -> np.ndarray:
        """What the actuator position sensors read of the ``applied`` inputs."""
        if not self._applied:
            return applied[:0]
        return applied[self._applied] + self._noise * self._rng.standard_normal(
            len(self._applied))

    def metadata(self) -> dict[str, Any]:
        return {**self.meta, "terminated": self.terminated, "stopped": self.stopped}


# -- replaying a recording's commands ------------------------------------------------------------
class ReplayPolicy:
    """The commands of a recording as a policy: step ``k`` returns the ``k``-th row of
    ``actions`` (normalised actions, one row per sample), from the first row again at an
    episode start (SB3's ``predict`` convention)."""

    def __init__(self, actions: np.ndarray) -> None:
        self.actions, self.k = np.asarray(actions, dtype=np.float64), 0

    def predict(self, obs: Any, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        if episode_start is not None and bool(np.any(episode_start)):
            self.k = 0
        action = self.actions[min(self.k, len(self.actions) - 1)]
        self.k += 1
        return action, None


def replay_policy(recording: Recording, system: System) -> ReplayPolicy:
    """The recorded commanded inputs (SI units) as normalised actions of ``system``: the inverse
    of its action map (least squares through an allocation matrix). An action beyond [-1, 1]
    (a command beyond the environment's actuator range) is clipped by the environment and
    flagged in ``info["action_clipped"]``. (A recording's commands are finite.)
    """
    return ReplayPolicy(system.actuation.to_action(recording.inputs))


def _replaying(recording: Recording, env_id: str, system: System) -> ReplayPolicy:
    """:func:`replay_policy`, for a record of the environment's own model."""
    if recording.model != system.model.name:
        raise ValueError(f"the replayed record is of model {recording.model!r}; {env_id} "
                         f"simulates {system.model.name!r}")
    return replay_policy(recording, system)


def release_state(recording: Recording, model: Any) -> np.ndarray:
    """The state a replay starts from: the model's nominal state, with the record's metadata
    ``initial_state`` (``{state: value}``, SI) where it gives one and the first sample of every
    measured state over both."""
    x0 = np.array(model.x0, dtype=float)
    given = recording.meta.get("initial_state")
    sources = [given if isinstance(given, Mapping) else {},
               {n: recording.data[n].iloc[0] for n in recording.measured_names}]
    for values in sources:
        for name, value in values.items():
            if name in model.state_names and np.isfinite(value):
                x0[model.state_names.index(name)] = float(value)
    return x0


def _replay_settings(recording: Recording, steps: int | None,
                     policy_options: Mapping[str, float],
                     env_kwargs: dict[str, Any]) -> tuple[int, dict[str, Any]]:
    """The steps and environment arguments of a replay: the record's length (or ``steps``,
    no more) at the record's sample period.

    :raises ValueError: policy options given, more steps than the record has, or another
        ``dt`` than the record's sample period.
    """
    if policy_options:
        raise ValueError(f"a replay plays the record's commands: no policy options "
                         f"({', '.join(policy_options)})")
    n = len(recording.time)
    if steps is not None and steps > n:
        raise ValueError(f"steps={steps} is more than the {n} samples of the replayed record")
    dt = round(recording.dt, 9)
    given = env_kwargs.get("dt", dt)
    if not math.isclose(given, dt, rel_tol=1e-6):
        raise ValueError(f"dt={given!r} is not the replayed record's sample period {dt} s")
    return (n if steps is None else steps), {**env_kwargs, "dt": dt}


def _actuators(chosen: ActuatorSensors, inputs: Sequence[str], env_id: str) -> tuple[str, ...]:
    """The inputs ``chosen`` for an actuator position sensor, in model order.
    :raises ValueError: a name that is not an input of the environment's model."""
    if isinstance(chosen, bool):
        return tuple(inputs) if chosen else ()
    if isinstance(chosen, str):
        chosen = [chosen]
    unknown = sorted(set(chosen) - set(inputs))
    if unknown:
        raise ValueError(f"actuator sensor(s) {unknown} are not inputs of {env_id}: choose "
                         f"from {', '.join(inputs)}")
    return tuple(name for name in inputs if name in chosen)


def _actuator_noise(noise: float | Mapping[str, float], actuators: Sequence[str]) -> np.ndarray:
    """Per actuator position sensor, its white noise's standard deviation (input units).
    :raises ValueError: a negative or non-finite value, or a name without a sensor."""
    if isinstance(noise, Mapping):
        unknown = sorted(set(noise) - set(actuators))
        if unknown:
            raise ValueError(f"actuator_noise names {unknown}, which have no actuator sensor "
                             f"({', '.join(actuators) or 'none recorded'})")
        values = np.array([float(noise.get(name, 0.0)) for name in actuators])
    else:
        values = np.full(len(actuators), float(noise))
    if not np.all(np.isfinite(values) & (values >= 0)):
        raise ValueError(f"actuator_noise={noise!r} is invalid: standard deviations >= 0 in "
                         "the inputs' units")
    return values


def why_terminated(system: Any, x: np.ndarray) -> str:
    """Which entry of the state ``x`` (state units) left the task's limits of ``system``
    (angles in degrees)."""
    model, task = system.model, system.task
    for i, name in enumerate(model.state_names):
        if not np.isfinite(x[i]):
            return f"{name} is not finite"
        if task.low[i] <= x[i] <= task.high[i]:
            continue
        unit = model.state_units[i]
        scale = 180 / math.pi if unit.startswith("rad") else 1.0
        unit = unit.replace("rad", "deg")
        return (f"{name} = {x[i] * scale:.4g} {unit} left its limits [{task.low[i] * scale:.4g}, "
                f"{task.high[i] * scale:.4g}] {unit}")
    return "the environment ended it"


@contextlib.contextmanager
def _bar(total: int, show: bool) -> Iterator[Any]:
    if not show:
        yield None
        return
    from tqdm import tqdm

    # counted by hand: a bar over range(steps) left by the last step's break ends one short
    with tqdm(total=total, desc="simulating", unit="step") as bar:
        yield bar


def simulate(env_id: str, steps: int | None, seed: int | None = None, policy: str = "prbs",
             env_kwargs: Mapping[str, Any] | None = None, progress: bool = False,
             disturbances: Sequence[str] = (), actuator_sensors: ActuatorSensors = (),
             actuator_noise: float | Mapping[str, float] = 0.0,
             replay: Recording | None = None, **policy_options: float) -> Recording:
    """Record ``steps`` steps of ``env_id`` under ``policy``: the commanded inputs and the
    sensor outputs, in SI units, with the model name, its parameters and the settings as
    metadata (``stopped`` says why the run ended: the steps reached, or the episode terminated
    and why). In memory: :func:`record` writes a long run to a file as it goes.

    The input columns hold what the policy commanded (``info["action_commanded"]``: clipped
    and scaled to the model's units), as a trial's log does; an actuator effect of
    ``effects=`` in ``env_kwargs`` (a rate limit, saturation, delay, ...) acts after it, and
    shows only in the motion, or in an actuator position sensor's column if one is asked for.

    :param disturbances: the model's disturbance channels to record too, exact (a logged
        command such as the ROV's morph ``s_cmd``, or an ideal wind or current sensor).
    :param actuator_sensors: inputs whose applied value (``info["action_applied"]``) is
        recorded too by a position sensor on the actuator, as the column ``<input>_applied``
        (``delta_applied``); True: every input. None by default: a log holds the command, and
        only some vessels log an actuator's position as well.
    :param actuator_noise: the white noise of those sensors, standard deviation in the input's
        units (a number for all, or by input name); seeded by ``seed`` in a stream of its own.
    :param replay: a recording whose commanded inputs replace the policy (:func:`replay_policy`):
        the environment is released from the record's first sample (:func:`release_state`) at
        the record's sample period, for ``steps`` steps (None: the record's length).
    :raises ValueError: ``steps < 2``, an unknown disturbance or input name, or a negative
        noise; a replayed record of another model, or longer ``steps`` than it has; before any
        simulation.
    """
    run = _Run(env_id, steps, seed, policy, env_kwargs, disturbances, policy_options,
               actuator_sensors, actuator_noise, replay)
    rows = np.array(list(run.rows(progress)))
    data = pd.DataFrame(rows, columns=run.columns)
    return Recording(data, run.system.model.name, run.params, run.metadata())


def record(path: str | Path, env_id: str, steps: int | None, seed: int | None = None,
           policy: str = "prbs", env_kwargs: Mapping[str, Any] | None = None,
           progress: bool = False, disturbances: Sequence[str] = (),
           actuator_sensors: ActuatorSensors = (),
           actuator_noise: float | Mapping[str, float] = 0.0,
           chunk_rows: int = CHUNK_ROWS, replay: Recording | None = None,
           **policy_options: float) -> Recorded:
    """:func:`simulate` into the recording file ``path`` (.csv with its sidecar, or .parquet)
    as it runs, ``chunk_rows`` rows at a time, so that memory stays bounded however long the
    run. The file appears whole at the end (:func:`~marine_envs.recording.stream_recording`).
    SIGINT (Ctrl-C) or SIGTERM stops the run after the step under way and keeps the rows
    recorded so far, a valid recording whose metadata says so; :attr:`Recorded.signal` tells
    which signal, and one that comes before two rows exist is passed on as if not caught.

    :raises ValueError: as :func:`simulate`, before any simulation.
    :raises marine_envs.files.WriteError: the file cannot be written (names it); the earlier
        file, if any, is left as it was.
    """
    run = _Run(env_id, steps, seed, policy, env_kwargs, disturbances, policy_options,
               actuator_sensors, actuator_noise, replay)
    steps, model = run.steps, run.system.model
    with _StopOnSignals() as stop, stream_recording(path, model.name, run.columns, run.params,
                                                   run.meta, chunk_rows) as out, \
            contextlib.closing(run.rows(progress)) as rows:  # closed (its bar too) on a break
        for row in rows:
            out.append(row)
            if stop.signal is not None:
                run.stopped = (f"interrupted by {signal.Signals(stop.signal).name} after "
                               f"{out.rows} of {steps} steps")
                break
        if stop.signal is not None and out.rows < 2:
            stop.pass_on()  # nothing worth keeping: the signal acts as if it was never caught
        out.meta.update(run.metadata())
    channels = run.system.channels
    return Recorded(Path(path), model.name, out.rows, steps, out.last_time, run.stopped,
                    stop.signal, tuple(model.input_names),
                    tuple(name for name in model.output_names if name in channels),
                    tuple(name for name in model.disturbance_names if name in disturbances),
                    run.actuators)


class _StopOnSignals:
    """Within the block, SIGINT and SIGTERM stop a run at its next step instead of raising in
    the middle of one (a row or a chunk written half-way): :attr:`signal` is set to the one
    received. Outside the main thread (where signals cannot be caught) nothing changes."""

    CAUGHT = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.signal: int | None = None
        self._before: dict[int, Any] = {}

    def __enter__(self) -> _StopOnSignals:
        if threading.current_thread() is threading.main_thread():
            for number in self.CAUGHT:
                self._before[number] = signal.signal(number, self._receive)
        return self

    def __exit__(self, *exc: object) -> None:
        self._restore()

    def _receive(self, number: int, frame: Any) -> None:
        self.signal = number

    def _restore(self) -> None:
        for number, handler in self._before.items():
            signal.signal(number, handler)
        self._before.clear()

    def pass_on(self) -> None:
        """Deliver the signal received to the handlers there were before the block."""
        self._restore()
        if self.signal is not None:
            signal.raise_signal(self.signal)
