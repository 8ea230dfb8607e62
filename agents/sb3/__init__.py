"""Train and evaluate Stable-Baselines3 agents on the marine environments.

SB3 trains on the native batched environment through :class:`~agents.sb3.vec_env.SB3VecEnv`
(or, with ``backend="dummy"``, on SB3's ``DummyVecEnv`` of single environments), optionally
behind a state estimator. Hyperparameters come from ``agents/hyperparams.yaml`` (RL-Zoo style).

One idea a module:

* :mod:`agents.sb3.hyperparams`: the algorithms by name, the hyperparameter file and a run's
  validated settings;
* :mod:`agents.sb3.vec_env`: the vector environments SB3 trains on (the batched-env adapter)
  and the failure penalty;
* :mod:`agents.sb3.callbacks`: validation keeping the best agent, checkpoints, progress, stop;
* :mod:`agents.sb3.runs`: a run's folder (its files, its lock, the saved agents in it);
* :mod:`agents.sb3.training`: :func:`~agents.sb3.training.train` and
  :func:`~agents.sb3.training.resume`;
* :mod:`agents.sb3.agent`: a trained agent in use (:func:`~agents.sb3.agent.load_agent`,
  :func:`~agents.sb3.agent.evaluate`);
* :mod:`agents.sb3.zoo`: the trained agents shipped with the package, loaded by name
  (``zoo:ROV-v0/residual_ppo``), published from a finished run (:func:`~agents.sb3.zoo.publish`).

Every public name is importable from here, as ``agents.sb3.train`` and so on.
"""

from __future__ import annotations

from . import zoo
from .agent import Agent, evaluate, load_agent
from .callbacks import KeepBest
from .hyperparams import (
    AGENT_SECTION,
    ALGO_EXTRAS,
    ALGOS,
    BACKENDS,
    COMPLETE,
    HYPERPARAMS,
    INTERRUPTED,
    ON_POLICY,
    OWN_SETTINGS,
    RUNNING,
    VALIDATION_SEED,
    agent_section,
    algorithm,
    check_hyperparams,
    estimator_choices,
    load_hyperparams,
    settings,
)
from .runs import (
    CHECKPOINTS,
    CONFIG,
    LOCK,
    OWNED,
    FallbackWarning,
    RunInUse,
    Saved,
    check_not_in_use,
    checkpoints,
    clear_run,
    existing_run,
    find_agent,
    latest,
    read_config,
    run_lock,
)
from .training import TrainResult, resume, train
from .vec_env import (
    ActionRatePenalty,
    FailurePenalty,
    RewardScale,
    SB3VecEnv,
    make_vec_env,
)
from .zoo import ZOO, ZooEntry, agent_path, is_zoo_name, kind_of

__all__ = [
    "AGENT_SECTION", "ALGOS", "ALGO_EXTRAS", "BACKENDS", "CHECKPOINTS", "COMPLETE", "CONFIG",
    "HYPERPARAMS", "INTERRUPTED", "LOCK", "ON_POLICY", "OWNED", "OWN_SETTINGS", "RUNNING",
    "VALIDATION_SEED", "ZOO", "ActionRatePenalty", "Agent", "FailurePenalty", "FallbackWarning",
    "KeepBest", "RewardScale", "RunInUse", "SB3VecEnv", "Saved", "TrainResult", "ZooEntry",
    "agent_path", "agent_section", "algorithm", "check_hyperparams", "check_not_in_use",
    "checkpoints", "clear_run", "estimator_choices", "evaluate", "existing_run", "find_agent",
    "is_zoo_name", "kind_of", "latest", "load_agent", "load_hyperparams", "make_vec_env",
    "read_config", "resume", "run_lock", "settings", "train", "zoo",
]
