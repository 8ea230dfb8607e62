"""The settings of a training run: the algorithms by name, the RL-Zoo style hyperparameter file
(:data:`HYPERPARAMS`, checked whole before any work) and a run's validated settings
(:func:`settings`, as its ``config.json`` starts).
"""

from __future__ import annotations

import contextlib
import copy
import difflib
import importlib.util
import inspect
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from stable_baselines3 import A2C, PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecNormalize

import marine_envs
from estimators import registry
from estimators.registry import RAW

from .residual import BASES as RESIDUAL_BASES

#: The algorithms by name; a string ``"module:Class"`` is imported on first use (an extra's).
ALGOS: dict[str, type[BaseAlgorithm] | str] = {
    "ppo": PPO, "sac": SAC, "td3": TD3, "a2c": A2C,
    "ppo_lstm": "sb3_contrib:RecurrentPPO",  # RL-Zoo's name; the `recurrent` extra
}
#: A hyperparameter entry ``residual_<algo>`` holds ``<algo>``'s settings as a correction to a
#: controller (read for ``marine train --residual``).
RESIDUAL_PREFIX = "residual_"
#: The extra that installs each algorithm imported on first use.
ALGO_EXTRAS = {"ppo_lstm": "recurrent"}
BACKENDS = ("native", "dummy")
HYPERPARAMS = Path(__file__).parents[1] / "hyperparams.yaml"
#: Algorithms that learn from fresh rollouts: their returns, not only observations, are scaled.
ON_POLICY = ("ppo", "a2c", "ppo_lstm")
#: First seed of the validation episodes: apart from training's (``seed``, ...) and from the
#: evaluation seeds (0, 1, ... in ``marine evaluate`` and ``marine bench``).
VALIDATION_SEED = 100_000
#: ``config.json``'s ``status``: training (or killed without saving: its checkpoints remain),
#: stopped by Ctrl-C and saved, or done.
RUNNING, INTERRUPTED, COMPLETE = "running", "interrupted", "complete"


# -- validation and hyperparameters ---------------------------------------------------------

def _check_choice(name: str, value: Any, choices: Sequence[Any]) -> None:
    if value not in choices:
        raise ValueError(f"{name}={value!r} is invalid: one of {tuple(choices)}")


def algorithm(name: str) -> type[BaseAlgorithm]:
    """The SB3 algorithm class called ``name`` (:data:`ALGOS`), importing an extra's on first
    use; a missing extra is named."""
    _check_choice("algo", name, tuple(ALGOS))
    found = ALGOS[name]
    if isinstance(found, str):
        module, cls = found.split(":")
        try:
            found = getattr(importlib.import_module(module), cls)
        except ImportError:
            raise ValueError(f"algo {name!r} needs {module.replace('_', '-')}: pip install "
                             f"'marine-envs[{ALGO_EXTRAS[name]}]'") from None
        ALGOS[name] = found
    return found


def load_hyperparams(env_id: str, algo: str, path: Path = HYPERPARAMS,
                     residual: bool = False) -> dict[str, Any]:
    """The settings of ``algo`` on ``env_id``: the file's ``default`` section for ``algo``,
    updated with the env's own entry; with ``residual``, those of ``residual_<algo>`` (the
    algorithm learning a correction to a controller), where the file has them. Keys:
    ``n_timesteps``, ``n_envs``, ``policy``, ``normalize`` (a bool or ``VecNormalize``'s keyword
    arguments), optional ``policy_kwargs``, ``failure_penalty`` and ``failure_cost_to_go``
    (:class:`~agents.sb3.vec_env.FailurePenalty`), ``action_rate_penalty``
    (:class:`~agents.sb3.vec_env.ActionRatePenalty`), ``reward_scale``
    (:class:`~agents.sb3.vec_env.RewardScale`), ``validation_episodes``
    (:class:`~agents.sb3.callbacks.KeepBest`), ``residual`` and ``residual_scale``
    (:mod:`agents.sb3.residual`: a correction to that controller), and algorithm keyword
    arguments (``learning_rate`` and ``clip_range`` may be RL-Zoo's ``"lin_<x>"``: decayed
    linearly to 0).

    The whole file is checked first (:func:`check_hyperparams`), not only the entry used.

    :raises ValueError: an unreadable file, an unknown section, algorithm or setting, or a
        value out of its range, named with the file.
    """
    _check_choice("env_id", env_id, tuple(marine_envs.ENVIRONMENTS))
    _check_choice("algo", algo, tuple(ALGOS))
    table = _read_table(path)
    names = (f"{RESIDUAL_PREFIX}{algo}", algo) if residual else (algo,)
    name = next((n for n in names if any(n in (table.get(key) or {})
                                         for key in ("default", env_id))), algo)
    sections = [(table.get(key) or {}).get(name) or {} for key in ("default", env_id)]
    params = {**sections[0], **sections[1]}
    if not params:
        raise ValueError(f"{path} has no settings for algo {algo!r} (nor a default)")
    missing = [key for key in ("n_timesteps", "n_envs", "policy") if key not in params]
    if missing:
        raise ValueError(f"{path}: the settings of {algo!r} on {env_id} lack {missing}")
    return params


def agent_section(path: Path) -> dict[str, Any]:
    """The ``agent:`` section of the hyperparameter file ``path`` (:data:`AGENT_SECTION`): what
    ``marine train --config`` takes on its command line (``env_id``, ``algo``, ``estimator``,
    ``seed``, ``out``, ``backend``, ``max_episode_steps``), each optional; empty if it has none.
    The whole file is checked first (:func:`check_hyperparams`).

    :raises ValueError: an unreadable file or a mistake in it, named with the file.
    """
    return dict(_read_table(Path(path)).get(AGENT_SECTION) or {})


def _read_table(path: Path) -> dict[str, Any]:
    """The hyperparameter file ``path``, read and checked (:func:`check_hyperparams`)."""
    import yaml  # here: only reading the settings needs PyYAML

    try:
        table = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ValueError(f"{path}: invalid YAML: {_one_line(error)}") from None
    check_hyperparams(table, path)
    return table


def check_hyperparams(table: Any, path: Path) -> None:
    """Check a hyperparameter table as read from ``path``: sections named by environment ids
    or ``default``, algorithms of :data:`ALGOS` in them, and in each the settings of ours
    (:data:`OWN_SETTINGS`) or keyword arguments of the algorithm (only their values when the
    algorithm's extra is not installed), each in its range: numbers of steps, batches and
    epochs >= 1, rates > 0 (or ``"lin_<x>"``), ``normalize`` a bool or ``VecNormalize``'s
    keyword arguments, ...

    An ``agent:`` section (:data:`AGENT_SECTION`) may give the run's command-line settings
    (:func:`agent_section`).

    :raises ValueError: the first mistake, named with ``path`` and where in it (a short id such
        as ``USV-v0`` for a section gets the full one suggested).
    """
    if not isinstance(table, dict):
        raise ValueError(f"{path}: must map environment ids (and 'default') to algorithms to "
                         "settings, as agents/hyperparams.yaml does")
    for section, entries in table.items():
        if section == AGENT_SECTION:
            _check_agent_section(entries, f"{path}: {AGENT_SECTION}")
            continue
        if section != "default" and section not in marine_envs.ENVIRONMENTS:
            raise ValueError(f"{path}: unknown section {section!r}{_env_suggestion(section)}: "
                             f"sections are 'default', '{AGENT_SECTION}' and environment ids "
                             f"({', '.join(marine_envs.ENVIRONMENTS)})")
        if not isinstance(entries, dict):
            raise ValueError(f"{path}: {section}: must map algorithms to their settings, "
                             "e.g. 'ppo: {n_steps: 512}'")
        for name, entry in entries.items():
            algo = str(name).removeprefix(RESIDUAL_PREFIX)
            if algo not in ALGOS:
                raise ValueError(f"{path}: {section}: unknown algorithm {name!r}"
                                 f"{_did_you_mean(name, ALGOS)}: one of {', '.join(ALGOS)} "
                                 f"(or {RESIDUAL_PREFIX}ALGO: its settings as a correction)")
            if not isinstance(entry, dict | None):
                raise ValueError(f"{path}: {section}: {name}: must map setting names to values")
            _check_settings(entry or {}, algo, f"{path}: {section}: {name}")


#: The section of a hyperparameter file that gives a run's command-line settings (a zoo agent's
#: re-train file has one), e.g. ``agent: {env_id: marine_envs/ROV-v0, algo: ppo, estimator: kf,
#: seed: 0, out: runs/zoo/ROV-v0/residual_ppo}``.
AGENT_SECTION = "agent"
#: What each entry of the ``agent:`` section must be (said so in an error).
_AGENT_RULES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "env_id": (lambda v: v in marine_envs.ENVIRONMENTS,
               f"one of {', '.join(marine_envs.ENVIRONMENTS)}"),
    "algo": (lambda v: v in ALGOS, f"one of {', '.join(ALGOS)}"),
    "estimator": (lambda v: isinstance(v, str) and v in estimator_choices(),
                  f"one of {', '.join(registry.names())}"),
    "seed": (lambda v: _is_int(v) and v >= 0, "an integer >= 0"),
    "out": (lambda v: isinstance(v, str) and bool(v.strip()), "a folder, e.g. runs/zoo/ROV"),
    "backend": (lambda v: v in BACKENDS, f"one of {', '.join(BACKENDS)}"),
    "max_episode_steps": (lambda v: v is None or (_is_int(v) and v >= 1),
                          "an integer >= 1 (or null: the registered length)"),
}


def _check_agent_section(section: Any, where: str) -> None:
    """Check the ``agent:`` section of a hyperparameter file (:func:`agent_section`).

    :raises ValueError: the first unknown entry or bad value, named with ``where``.
    """
    if not isinstance(section, dict):
        raise ValueError(f"{where}: must map {', '.join(_AGENT_RULES)} to values, e.g. "
                         "'agent: {env_id: marine_envs/ROV-v0, algo: ppo, estimator: kf}'")
    for key, value in section.items():
        if key not in _AGENT_RULES:
            raise ValueError(f"{where}: unknown entry {key!r}{_did_you_mean(key, _AGENT_RULES)}: "
                             f"one of {', '.join(_AGENT_RULES)}")
        check, what = _AGENT_RULES[key]
        if not check(value):
            hint = _env_suggestion(value) if key == "env_id" else ""
            raise ValueError(f"{where}: {key}={value!r} is invalid{hint}: {what}")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_rate(value: Any) -> bool:
    """A number > 0, or RL-Zoo's ``"lin_<x>"`` with ``x`` > 0."""
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            value = float(value[4:])
        except ValueError:
            return False
    return _is_number(value) and value > 0


_AT_LEAST_1 = (lambda v: _is_int(v) and v >= 1, "an integer >= 1")
_RATE = (_is_rate, "a number > 0, or 'lin_<x>' (decayed linearly from x > 0 to 0), "
                   "e.g. 'lin_3e-4'")
_FRACTION = (lambda v: _is_number(v) and 0 <= v <= 1, "a number in [0, 1]")
#: What each setting's value must be (said so in an error); the algorithm checks the others.
_RULES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "n_timesteps": _AT_LEAST_1, "n_envs": _AT_LEAST_1, "n_steps": _AT_LEAST_1,
    "batch_size": _AT_LEAST_1, "n_epochs": _AT_LEAST_1, "buffer_size": _AT_LEAST_1,
    "learning_starts": (lambda v: _is_int(v) and v >= 0, "an integer >= 0"),
    "gradient_steps": (lambda v: _is_int(v) and (v >= 1 or v == -1),
                       "an integer >= 1, or -1 (as many as environment steps)"),
    "validation_episodes": (lambda v: _is_int(v) and v >= 0,
                            "an integer >= 1, or 0 (no validation)"),
    "learning_rate": _RATE, "clip_range": _RATE,
    "gamma": _FRACTION, "gae_lambda": _FRACTION, "tau": _FRACTION,
    "failure_penalty": (lambda v: _is_number(v) and v >= 0, "a finite number >= 0"),
    "failure_cost_to_go": (lambda v: isinstance(v, bool), "true or false"),
    "action_rate_penalty": (lambda v: _is_number(v) and v >= 0, "a finite number >= 0"),
    "reward_scale": (lambda v: _is_number(v) and v > 0, "a finite number > 0"),
    "normalize": (lambda v: isinstance(v, bool | Mapping),
                  "true, false or VecNormalize's keyword arguments, e.g. {clip_reward: 10000}"),
    "policy": (lambda v: isinstance(v, str) and bool(v), "a policy name, e.g. MlpPolicy"),
    "policy_kwargs": (lambda v: isinstance(v, Mapping),
                      "the policy's keyword arguments, e.g. {net_arch: [64, 64]}"),
    "residual": (lambda v: v in RESIDUAL_BASES, f"one of {', '.join(RESIDUAL_BASES)} (the "
                 "controller the agent corrects)"),
    "residual_scale": (lambda v: _is_number(v) and 0 < v <= 2,
                       "a number in (0, 2]: the correction's bound, a fraction of each "
                       "action's half range"),
}
#: Settings of ours (:func:`load_hyperparams`); the others are the algorithm's keyword arguments.
OWN_SETTINGS = ("n_timesteps", "n_envs", "policy", "normalize", "policy_kwargs",
                "failure_penalty", "failure_cost_to_go", "action_rate_penalty",
                "reward_scale", "validation_episodes", "residual", "residual_scale")
#: The algorithms' keyword arguments that :func:`~agents.sb3.training.train` sets itself: not
#: settings.
_SET_BY_TRAIN = ("self", "policy", "env", "seed", "device", "verbose", "tensorboard_log",
                 "_init_setup_model")


def _check_settings(settings: Mapping[str, Any], algo: str, where: str) -> None:
    """Check the settings of one ``algo`` entry (see :func:`check_hyperparams`).

    :param where: what the settings are, for the error (e.g. ``"FILE: default: ppo"``).
    :raises ValueError: the first unknown setting or bad value, named with ``where``.
    """
    _check_choice("algo", algo, tuple(ALGOS))
    try:
        cls: type[BaseAlgorithm] | None = algorithm(algo)
    except ValueError:  # an extra that is not installed: its names are unknown here
        cls = None
    known = None if cls is None else (*OWN_SETTINGS, *_keywords(cls))
    for key, value in settings.items():
        if known is not None and key not in known:
            raise ValueError(f"{where}: unknown setting {key!r}{_did_you_mean(key, known)}")
        check, what = _RULES.get(key, (lambda v: True, ""))
        if not check(value):
            raise ValueError(f"{where}: {key}={value!r} is invalid: {what}{_text_hint(value)}")
    normalize = settings.get("normalize")
    if isinstance(normalize, Mapping):
        allowed = _keywords(VecNormalize, ("self", "venv"))
        unknown = [key for key in normalize if key not in allowed]
        if unknown:
            raise ValueError(f"{where}: normalize: unknown setting {unknown[0]!r}"
                             f"{_did_you_mean(unknown[0], allowed)}: VecNormalize takes "
                             f"{', '.join(allowed)}")
    policies, policy = getattr(cls, "policy_aliases", {}), settings.get("policy")
    if policies and policy is not None and policy not in policies:
        raise ValueError(f"{where}: policy={policy!r} is invalid: one of {', '.join(policies)}"
                         f"{_did_you_mean(policy, policies)}")


def _keywords(cls: type, leave_out: Sequence[str] = _SET_BY_TRAIN) -> tuple[str, ...]:
    """The keyword arguments of ``cls``, but those in ``leave_out``."""
    parameters = inspect.signature(cls.__init__).parameters.values()
    return tuple(p.name for p in parameters if p.name not in leave_out
                 and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD))


def _did_you_mean(name: Any, choices: Sequence[str] | Mapping[str, Any]) -> str:
    close = difflib.get_close_matches(str(name), list(choices), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _env_suggestion(name: Any) -> str:
    """`` (did you mean 'marine_envs/USV-v0'?)`` for ``USV-v0``, ``usv`` or a near miss."""
    for full in marine_envs.ENVIRONMENTS:
        short = full.split("/")[1].lower()
        if str(name).lower().removeprefix("marine_envs/") in (short, short.removesuffix("-v0")):
            return f" (did you mean {full!r}?)"
    return _did_you_mean(name, marine_envs.ENVIRONMENTS)


def _text_hint(value: Any) -> str:
    """A hint for a number YAML read as text: PyYAML (YAML 1.1) needs a dot in ``3.0e-4``."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return ""
        return " (YAML reads it as text: write the number with a decimal point, e.g. 3.0e-4)"
    return ""


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split())


def _schedule(value: Any) -> Any:
    """RL-Zoo's ``"lin_<x>"``: ``x`` decayed linearly to 0 over training (SB3 passes the
    remaining fraction of training, 1 -> 0); any other value as it is."""
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            raise ValueError(f"schedule {value!r} is invalid: 'lin_' and a number, e.g. "
                             "'lin_3e-4'") from None
        return lambda remaining: remaining * start
    return value


def estimator_choices() -> tuple[str | None, ...]:
    """What an agent may see: None (= ``"raw"``, the sensors), ``"true"`` (the true state) or
    a registered estimator (:data:`estimators.registry.ESTIMATORS`)."""
    return (None, *registry.names())


def settings(env_id: str, algo: str = "ppo", estimator: str | None = None,
             timesteps: int | None = None, seed: int = 0, n_envs: int | None = None,
             backend: str = "native", hyperparams: Mapping[str, Any] | None = None,
             max_episode_steps: int | None = None, hyperparams_file: Path = HYPERPARAMS
             ) -> dict[str, Any]:
    """The validated settings of a :func:`~agents.sb3.training.train` run, as its ``config.json``
    starts.

    :raises ValueError: an unknown env id, algorithm, estimator or backend, a step or
        environment count that is not a positive integer, or a setting of the file or of
        ``hyperparams`` out of its range or unknown (:func:`check_hyperparams`), naming it,
        before any work.
    """
    algorithm(algo)  # an extra's algorithm is imported here: a missing extra named up front
    _check_choice("estimator", estimator, estimator_choices())
    _check_choice("backend", backend, BACKENDS)
    _check_settings(dict(hyperparams or {}), algo, "hyperparams")
    residual = (hyperparams or {}).get("residual") is not None
    params = {**load_hyperparams(env_id, algo, Path(hyperparams_file), residual),
              **dict(hyperparams or {})}
    yaml_timesteps, yaml_envs = params.pop("n_timesteps"), params.pop("n_envs")
    timesteps = int(yaml_timesteps if timesteps is None else timesteps)
    if timesteps <= 0:
        raise ValueError(f"timesteps={timesteps!r} is invalid: a positive number of steps")
    n_envs = yaml_envs if n_envs is None else n_envs
    if not (isinstance(n_envs, int) and n_envs >= 1):
        raise ValueError(f"n_envs={n_envs!r} is invalid: an integer >= 1")
    return {"env_id": env_id, "algo": algo, "estimator": estimator or RAW, "seed": seed,
            "n_envs": n_envs, "backend": backend, "max_episode_steps": max_episode_steps,
            "hyperparams_file": str(hyperparams_file), "hyperparams": copy.deepcopy(params),
            "status": RUNNING, "timesteps": 0, "target_timesteps": timesteps,
            # about five checkpoints (and validations) a run, in vector steps of n_envs boats
            "checkpoint_every": max(1, math.ceil(timesteps / 5 / n_envs)),
            "wall_seconds": 0.0}



@contextlib.contextmanager
def _torch_threads(threads: int | None) -> Iterator[None]:
    """Torch's intra-op threads set to ``threads`` for the block (None: left as they are)."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads or before)
    try:
        yield
    finally:
        torch.set_num_threads(before)


