"""Train an SB3 agent into a run folder (:func:`train`) and continue a stopped one
(:func:`resume`): the environments and the model built from the run's settings, Ctrl-C or
SIGTERM stopping at the next step where everything is saved whole.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import errno
import importlib.util
import math
import signal
import threading
import time
import traceback
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.utils import configure_logger
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

from estimators.registry import RAW
from marine_envs.files import WriteError

from .. import evaluation
from .callbacks import KeepBest, _Checkpoints, _Progress, _StopWhen
from .hyperparams import (
    COMPLETE,
    HYPERPARAMS,
    INTERRUPTED,
    ON_POLICY,
    RUNNING,
    VALIDATION_SEED,
    _schedule,
    _torch_threads,
    algorithm,
    settings,
)
from .residual import residual_of, zero_output
from .runs import (
    CHECKPOINTS,
    Saved,
    _save_agent,
    _write_config,
    clear_run,
    existing_run,
    latest,
    read_config,
    run_lock,
)
from .vec_env import ActionRatePenalty, FailurePenalty, RewardScale, make_vec_env


@dataclasses.dataclass
class TrainResult:
    """What :func:`train` did: output directory, environment steps taken in all (a resumed run
    counts its earlier steps), wall-clock time of this session (s) and its throughput
    (environment steps per second, learning and validation included); with validation, the
    score of the agent kept in ``model.zip`` (timesteps, failed, cost); whether a signal
    stopped it (it was saved all the same), the step count it started from and the signal
    (``signal.SIGINT`` or ``signal.SIGTERM``; None when it ran to its end)."""

    out: Path
    timesteps: int
    wall_seconds: float
    steps_per_second: float
    selected: dict[str, float] | None = None
    interrupted: bool = False
    resumed_from: int = 0
    stop_signal: int | None = None


def _importable(*modules: str) -> bool:
    return all(importlib.util.find_spec(m) is not None for m in modules)


class _StopSignals:
    """While active: the first SIGINT (Ctrl-C) or SIGTERM (a scheduler's or ``kill``'s stop)
    asks training to stop at the next step, where everything can be saved whole; a second
    one interrupts at once (``KeyboardInterrupt``: a file being written is left as it was).
    Only in the main thread (where Python delivers signals); elsewhere they keep their
    handlers."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        #: the signal that asked to stop, None until one did
        self.received: int | None = None
        self._previous: dict[int, Any] = {}

    @property
    def requested(self) -> bool:
        return self.received is not None

    def __enter__(self) -> _StopSignals:
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._handle) for s in self.SIGNALS}
        return self

    def __exit__(self, *exc: object) -> None:
        for number, handler in self._previous.items():
            # None: a handler installed outside Python, which cannot be put back
            signal.signal(number, signal.SIG_DFL if handler is None else handler)

    def _handle(self, signum: int, frame: Any) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.received = signum


def train(env_id: str, algo: str = "ppo", estimator: str | None = None,
          timesteps: int | None = None, out: Path = Path("runs/sb3"), seed: int = 0,
          n_envs: int | None = None, backend: str = "native", progress_bar: bool = True,
          hyperparams: Mapping[str, Any] | None = None,
          max_episode_steps: int | None = None, torch_threads: int | None = 1,
          hyperparams_file: Path = HYPERPARAMS, force: bool = True) -> TrainResult:
    """Train ``algo`` on ``env_id`` and save ``model.zip``, ``vecnormalize.pkl`` (when the
    settings normalise), ``config.json`` and ``checkpoints/`` into ``out``. With the setting
    ``validation_episodes`` (:class:`~agents.sb3.callbacks.KeepBest`), ``model.zip`` is the best
    validated agent, ``last_model.zip`` the last, and ``config.json`` has each validation's scores.

    ``config.json`` is written first (``"status": "running"``) and rewritten at the end
    (``"complete"``, with the step count). Ctrl-C (SIGINT) or SIGTERM stops training at the
    next step and saves the agent as at the end (``"interrupted"``;
    :attr:`TrainResult.interrupted`); :func:`resume` continues it. Every file is written whole
    (a full disk or a kill leaves the earlier one, or none), and the folder is locked while
    training writes it (:func:`~agents.sb3.runs.run_lock`).

    :param timesteps: environment steps (default: the YAML's ``n_timesteps``).
    :param n_envs: parallel environments (default: the YAML's).
    :param hyperparams: overrides of the YAML's settings (e.g. ``{"n_steps": 128}``).
    :param torch_threads: torch's intra-op threads while training (None: leave as is). One by
        default: small MLPs gain nothing from more, and torch's threads spinning against
        numpy's made training 20x slower on 2 cores.
    :param hyperparams_file: the RL-Zoo style YAML of settings (default: the package's).
    :param force: replace a run already in ``out``, clearing what it wrote
        (:func:`~agents.sb3.runs.clear_run`), so that two runs never mix; False: refuse such a
        folder (what ``marine train`` does without ``--force``).
    :raises FileExistsError: ``out`` holds a run and ``force`` is False.
    :raises RunInUse: another training is writing ``out`` (``force`` or not).
    :raises marine_envs.files.WriteError: a file could not be written (named).
    """
    config = settings(env_id, algo, estimator, timesteps, seed, n_envs, backend, hyperparams,
                      max_episode_steps, hyperparams_file)
    out = Path(out)
    with run_lock(out):
        held = existing_run(out)
        if held and not force:
            raise FileExistsError(f"{out} already holds a training run ({', '.join(held)}): "
                                  "continue it with --resume, or replace it with --force")
        return _run(config, out, None, progress_bar, torch_threads)


def resume(run: Path, timesteps: int | None = None, progress_bar: bool = True,
           torch_threads: int | None = 1) -> TrainResult:
    """Continue the training run in ``run`` from its last saved agent
    (:func:`~agents.sb3.runs.latest`), with the settings of its ``config.json``, the normalisation
    statistics saved with the agent and its step count (SB3's ``reset_num_timesteps=False``:
    schedules and checkpoint names go on), to ``timesteps`` steps in all (default: the run's own
    target). An off-policy algorithm's replay buffer is not saved: it refills from the resumed
    policy.

    :raises FileNotFoundError: ``run`` is not a run folder.
    :raises ValueError: nothing to resume from, or ``timesteps`` not beyond its steps.
    :raises RunInUse: another training is writing ``run``.
    """
    run = Path(run)
    read_config(run)  # a run folder: before the lock, which would make one
    with run_lock(run):
        saved = latest(run)
        config = read_config(run)
        target = int(config.get("target_timesteps", config.get("timesteps", 0))
                     if timesteps is None else timesteps)
        assert saved.timesteps is not None
        if target <= saved.timesteps:
            raise ValueError(f"{run} has trained {saved.timesteps} of {target} steps: nothing "
                             "to resume; give --timesteps beyond it to train further")
        config.update(status=RUNNING, target_timesteps=target,
                      estimator=config.get("estimator") or RAW)
        config.setdefault("checkpoint_every", max(1, math.ceil(target / 5 / config["n_envs"])))
        return _run(config, run, saved, progress_bar, torch_threads)


#: Validation episodes of a residual run whose settings give none: its correction must earn its
#: place against the controller it corrects.
RESIDUAL_VALIDATION_EPISODES = 8


@dataclasses.dataclass(frozen=True)
class _Penalty:
    """A run's reward shaping (training only): the failure penalty (reward units), whether a
    failure also costs the rest of its episode at its own rate
    (:class:`~agents.sb3.vec_env.FailurePenalty`), the weight of the action-rate penalty
    (:class:`~agents.sb3.vec_env.ActionRatePenalty`) and a fixed reward scale
    (:class:`~agents.sb3.vec_env.RewardScale`)."""

    penalty: float = 0.0
    cost_to_go: bool = False
    action_rate: float = 0.0
    reward_scale: float = 1.0


def _algorithm_kwargs(config: Mapping[str, Any]) -> tuple[dict[str, Any], str, bool,
                                                         dict[str, Any], _Penalty, int]:
    """From the run's settings: the algorithm's keyword arguments (schedules built), the
    policy, whether and how to normalise, the failure penalty and the validation episodes."""
    params = copy.deepcopy(dict(config["hyperparams"]))
    policy, normalize = params.pop("policy"), params.pop("normalize", False)
    # normalize: a bool, or VecNormalize's keyword arguments (RL-Zoo style)
    normalize_kwargs = dict(normalize) if isinstance(normalize, Mapping) else {}
    penalty = _Penalty(float(params.pop("failure_penalty", 0.0)),
                       bool(params.pop("failure_cost_to_go", False)),
                       float(params.pop("action_rate_penalty", 0.0)),
                       float(params.pop("reward_scale", 1.0)))
    validation_episodes = params.pop("validation_episodes", 0)
    base, _ = residual_of(params)
    for key in ("residual", "residual_scale"):  # the environments' (:func:`_environments`)
        params.pop(key, None)
    if base is not None and not validation_episodes:
        # a correction is kept only where validation finds it better than the controller
        validation_episodes = RESIDUAL_VALIDATION_EPISODES
    for key in ("learning_rate", "clip_range"):
        if key in params:
            params[key] = _schedule(params[key])
    return params, policy, bool(normalize), normalize_kwargs, penalty, validation_episodes


def _environments(config: Mapping[str, Any], saved: Saved | None, params: Mapping[str, Any],
                  normalize: bool, normalize_kwargs: dict[str, Any], penalty: _Penalty
                  ) -> VecEnv:
    """The training environments: seeded on, after the steps already taken (a resumed run
    sees new episodes), behind the failure and action-rate penalties, the reward scale and the
    normalisation (restored)."""
    start = 0 if saved is None else int(saved.timesteps or 0)
    base, scale = residual_of(config["hyperparams"])
    venv = make_vec_env(config["env_id"], config["n_envs"], config["estimator"],
                        config["seed"] + start, config["backend"], config["max_episode_steps"],
                        residual=base, residual_scale=scale)
    if penalty.penalty or penalty.cost_to_go:
        steps = evaluation.episode_steps(config["env_id"], config["max_episode_steps"]) \
            if penalty.cost_to_go else None
        venv = FailurePenalty(venv, penalty.penalty, steps)
    if penalty.action_rate:
        venv = ActionRatePenalty(venv, penalty.action_rate)
    if penalty.reward_scale != 1.0:
        venv = RewardScale(venv, penalty.reward_scale)
    if not normalize:
        return venv
    if saved is not None and saved.vecnormalize is not None:
        venv = VecNormalize.load(str(saved.vecnormalize), venv)
        venv.training = True
        return venv
    # rewards too only on-policy: a replay buffer would keep stale scales
    normalize_kwargs = {"gamma": params.get("gamma", 0.99),
                        "norm_reward": config["algo"] in ON_POLICY, **normalize_kwargs}
    return VecNormalize(venv, **normalize_kwargs)


def _run(config: dict[str, Any], out: Path, saved: Saved | None, progress_bar: bool,
         torch_threads: int | None) -> TrainResult:
    """Train (or go on training ``saved``) to ``config["target_timesteps"]``, save and
    rewrite ``config.json``; SIGINT or SIGTERM stops at the next step and saves the same way.
    A new run's old files are cleared and ``config.json`` written once the environments and
    the model are built: a setting they refuse leaves no trace. The caller holds the lock of
    ``out`` (:func:`~agents.sb3.runs.run_lock`)."""
    algo, target = config["algo"], int(config["target_timesteps"])
    params, policy, normalize, normalize_kwargs, penalty, episodes = _algorithm_kwargs(config)
    venv = _environments(config, saved, params, normalize, normalize_kwargs, penalty)
    tensorboard = str(out / "tb") if _importable("tensorboard") else None
    start = 0 if saved is None else int(saved.timesteps or 0)
    if saved is None:
        try:
            model = algorithm(algo)(policy, venv, seed=config["seed"], device="cpu", verbose=0,
                                    tensorboard_log=tensorboard, **params)
        except TypeError as error:  # a setting the algorithm does not take (a typo?)
            venv.close()
            raise ValueError(f"{config.get('hyperparams_file', 'the settings')}: {algo}: "
                             f"{error}") from None
        if residual_of(config["hyperparams"])[0] is not None:
            zero_output(model)  # the untrained correction is none: the agent starts as the base
        clear_run(out)
    else:
        schedules = {k: params[k] for k in ("learning_rate", "clip_range") if k in params}
        model = algorithm(algo).load(saved.model, env=venv, device="cpu",
                                     custom_objects=schedules, tensorboard_log=tensorboard)
        model.num_timesteps = start
        model.set_random_seed(config["seed"] + start)
    with _StopSignals() as stop:  # from here on, a stop request saves the run
        _write_config(out, config)
        keeper = _keeper(config, out, episodes, stop)
        callbacks: list[BaseCallback] = [
            _Checkpoints(config["checkpoint_every"], out / CHECKPOINTS),
            _StopWhen(lambda: stop.requested)]
        if keeper is not None:
            callbacks.append(keeper)
        progress = _Progress(start, target) if progress_bar and _importable("tqdm") else None
        if progress is not None:
            callbacks.append(progress)
        logger = configure_logger(0, tensorboard, type(model).__name__, saved is None)
        model.set_logger(logger)  # SB3's own, as learn() would make it, but closed here
        began = time.perf_counter()
        try:
            with _torch_threads(torch_threads), _log_closed(logger, out / "tb"):
                model.learn(target - start, callback=callbacks,
                            reset_num_timesteps=saved is None)
        finally:
            if progress is not None:
                progress.close(int(model.num_timesteps))
        wall = time.perf_counter() - began
        return _finish(model, venv, keeper, config, out, wall, start, stop.received)


@contextlib.contextmanager
def _log_closed(logger: Logger, folder: Path) -> Iterator[None]:
    """Close SB3's ``logger`` (its TensorBoard log is in ``folder``) when the block ends, and
    report a write error of the log (a full disk) as one naming ``folder``: TensorBoard writes
    in a thread of its own, whose error SB3's logger raises later without a file name (and
    the thread prints its traceback, left out here: the error is reported once)."""
    excepthook = threading.excepthook

    def quiet(args: Any) -> None:
        if not (isinstance(args.exc_value, OSError) and _from_tensorboard(args.exc_value)):
            excepthook(args)

    threading.excepthook = quiet
    try:
        try:
            yield
        except BaseException:
            with contextlib.suppress(OSError):  # an error is on its way: one is enough
                logger.close()
            raise
        logger.close()  # the last records written (or their error raised) here
    except OSError as error:
        if isinstance(error, WriteError) or not _from_tensorboard(error):
            raise
        raise WriteError(error.errno or errno.EIO, f"cannot write {folder}: "
                         f"{error.strerror or error}", str(folder)) from error
    finally:
        threading.excepthook = excepthook


def _from_tensorboard(error: BaseException) -> bool:
    """Whether ``error`` was raised in TensorBoard's code."""
    return any("tensorboard" in frame.f_code.co_filename
               for frame, _ in traceback.walk_tb(error.__traceback__))


def _keeper(config: Mapping[str, Any], out: Path, episodes: int, stop: _StopSignals
            ) -> KeepBest | None:
    """:class:`~agents.sb3.callbacks.KeepBest` for the run (carrying on a resumed run's
    validations), or None."""
    if not episodes:
        return None
    residual = residual_of(config["hyperparams"])[0] is not None
    keeper = KeepBest(config["env_id"], config["estimator"], episodes,
                      config["checkpoint_every"], out, config["max_episode_steps"],
                      stopped=lambda: stop.requested, agent_config=config,
                      from_start=residual)
    validation = config.get("validation") or {}
    keeper.history = list(validation.get("history", []))
    keeper.best = validation.get("selected")
    return keeper


def _finish(model: BaseAlgorithm, venv: VecEnv, keeper: KeepBest | None,
            config: dict[str, Any], out: Path, wall: float, start: int,
            stop_signal: int | None) -> TrainResult:
    """Save the agent (model.zip, or last_model.zip beside KeepBest's choice) and its
    statistics, and write the final ``config.json``."""
    steps = int(model.num_timesteps)
    last = "" if keeper is None else "last_"  # model.zip is then KeepBest's choice
    _save_agent(model, out / f"{last}model.zip", out / f"{last}vecnormalize.pkl")
    if keeper is not None and not (out / "model.zip").exists():
        # stopped before the first validation: the last agent is all there is
        _save_agent(model, out / "model.zip", out / "vecnormalize.pkl")
    result = TrainResult(out, steps, wall, (steps - start) / max(wall, 1e-9),
                         None if keeper is None else keeper.best, stop_signal is not None,
                         start, stop_signal)
    config.update(status=COMPLETE if stop_signal is None else INTERRUPTED, timesteps=steps,
                  wall_seconds=float(config.get("wall_seconds", 0.0)) + wall,
                  steps_per_second=result.steps_per_second)
    if keeper is not None:
        config["validation"] = {"first_seed": VALIDATION_SEED, "episodes": keeper.episodes,
                                "selected": keeper.best, "history": keeper.history}
    _write_config(out, config)
    venv.close()
    return result


