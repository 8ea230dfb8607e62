"""The zoo: trained agents shipped with the package, loaded by name (``zoo:ROV-v0/residual_ppo``)
on a fresh install.

Each agent is a folder ``agents/zoo/{Env}-v0/{kind}/`` (:data:`ZOO`) holding what
:func:`~agents.sb3.agent.load_agent` needs and no more: ``model.zip``, ``vecnormalize.pkl`` (when
the run normalised), the run's ``config.json`` (without paths of the machine that trained it)
and ``card.json``: how it was trained (steps, wall time, machine, date) and, once measured, its
cost ratio to LQR behind the same estimator on the tuning and the held-out evaluation seeds.
Beside the folder, ``agents/zoo/{Env}-v0/{kind}.yaml`` re-trains it:
``marine train --config agents/zoo/ROV-v0/residual_ppo.yaml``.

:func:`publish` copies a finished ``marine train`` run in, :func:`record_scores` adds its
measured scores, :func:`entries` and :func:`path_of` find what is shipped.
"""

from __future__ import annotations

import dataclasses
import datetime
import difflib
import json
import math
import os
import platform
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from marine_envs.files import write_json, write_text

from .hyperparams import AGENT_SECTION, COMPLETE, RESIDUAL_PREFIX
from .runs import CONFIG, find_agent, read_config

#: The shipped agents: ``{Env}-v0/{kind}/`` folders and their ``{Env}-v0/{kind}.yaml``.
ZOO = Path(__file__).parents[1] / "zoo"
#: What starts an agent's name in the zoo, as in ``zoo:ROV-v0/residual_ppo``.
PREFIX = "zoo:"
CARD = "card.json"
#: The score sets a card holds: seeds used to choose settings, and seeds never used for that.
SCORE_SETS = ("tuning", "held_out")
#: The entries of one score set: required, then optional (what each must be).
_SCORE_REQUIRED = ("seeds", "cost_ratio")
_SCORE_KEYS = {
    "seeds": "a list of distinct integer seeds",
    "cost_ratio": "the agent's mean cost over LQR's behind the same estimator, a number > 0",
    "cost": "the agent's mean cost, a number >= 0",
    "lqr_cost": "LQR's mean cost, a number >= 0",
    "failed": "the agent's failed episodes, an integer >= 0",
    "lqr_failed": "LQR's failed episodes, an integer >= 0",
    "measured": "when, a date as text",
    "note": "a remark, as text",
}


@dataclasses.dataclass(frozen=True)
class ZooEntry:
    """A shipped agent: its ``name`` (``zoo:ROV-v0/residual_ppo``), its folder ``path`` and the
    contents of its ``card.json``."""

    name: str
    path: Path
    card: dict[str, Any]

    @property
    def env_id(self) -> str:
        return str(self.card["env_id"])

    @property
    def kind(self) -> str:
        return str(self.card["kind"])


# -- finding shipped agents -------------------------------------------------------------------

def _zoo(zoo: Path | None) -> Path:
    return ZOO if zoo is None else Path(zoo)  # ZOO looked up at each call (tests point it away)


def _name(env_id: str, kind: str) -> str:
    return f"{PREFIX}{env_id.split('/')[-1]}/{kind}"


def entries(zoo: Path | None = None) -> list[ZooEntry]:
    """The agents shipped in ``zoo`` (default :data:`ZOO`), by name; none if it does not exist.

    :raises ValueError: a ``card.json`` that is not a JSON object (named).
    """
    found = []
    for card in sorted(_zoo(zoo).glob(f"*/*/{CARD}")):
        if not (card.parent / "model.zip").is_file():
            continue  # a publication cut short: no agent
        found.append(ZooEntry(f"{PREFIX}{card.parent.parent.name}/{card.parent.name}",
                              card.parent, _read_card(card)))
    return found


def names(zoo: Path | None = None) -> list[str]:
    """The names of the agents shipped in ``zoo`` (default :data:`ZOO`), e.g.
    ``zoo:ROV-v0/residual_ppo``."""
    return [entry.name for entry in entries(zoo)]


def is_zoo_name(text: str | os.PathLike[str]) -> bool:
    """Whether ``text`` names a zoo agent (``zoo:...``) rather than a path."""
    return isinstance(text, str) and text.startswith(PREFIX)


def path_of(name: str, zoo: Path | None = None) -> Path:
    """The folder of the shipped agent ``name`` (``zoo:ROV-v0/residual_ppo``; the full env id
    ``zoo:marine_envs/ROV-v0/...`` is taken too).

    :raises ValueError: not a zoo name, or no such agent (the message lists those shipped and
        suggests a close one).
    """
    example = "e.g. zoo:ROV-v0/residual_ppo"
    if not is_zoo_name(name):
        raise ValueError(f"{name!r} is not a zoo name: 'zoo:<Env>-v0/<kind>', {example}")
    parts = name[len(PREFIX):].removeprefix("marine_envs/").split("/")
    shipped = names(zoo)
    if len(parts) == 2 and all(parts) and f"{PREFIX}{parts[0]}/{parts[1]}" in shipped:
        return _zoo(zoo) / parts[0] / parts[1]
    if not shipped:
        raise ValueError(f"no agent {name!r}: the zoo ({_zoo(zoo)}) is empty")
    close = difflib.get_close_matches(name, shipped, n=1, cutoff=0.5)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise ValueError(f"no agent {name!r} in the zoo{hint}: it holds {', '.join(shipped)}")


def agent_path(name_or_path: str | os.PathLike[str]) -> Path:
    """Where the agent ``name_or_path`` is: a zoo name's folder (:func:`path_of`), else the
    path itself (a run folder or a model file)."""
    return path_of(name_or_path) if is_zoo_name(name_or_path) else Path(name_or_path)


def _read_card(path: Path) -> dict[str, Any]:
    try:
        card = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: invalid JSON: {error}") from None
    missing = [key for key in ("env_id", "kind") if key not in (card or {})]
    if not isinstance(card, dict) or missing:
        raise ValueError(f"{path} is not a zoo card: missing {missing}")
    return card


# -- publishing ---------------------------------------------------------------------------------

def kind_of(config: Mapping[str, Any]) -> str:
    """The agent's kind from its run's ``config.json``: the algorithm (``ppo``), or
    ``residual_<algo>`` when its actions correct a controller's (the setting ``residual``)."""
    return f"{RESIDUAL_PREFIX}{config['algo']}" if config["hyperparams"].get("residual") \
        else str(config["algo"])


def publish(run: Path, scores: Mapping[str, Any] | None = None, *, zoo: Path | None = None,
            replace: bool = False) -> ZooEntry:
    """Copy the finished ``marine train`` run folder ``run`` into the zoo as
    ``zoo:{Env}-v0/{kind}`` (:func:`kind_of`): its ``model.zip`` (with validation, the agent it
    kept), ``vecnormalize.pkl`` if any and its ``config.json`` with ``hyperparams_file`` made the
    zoo's re-train YAML (relative to the folder holding ``zoo``); writes ``card.json`` and the
    re-train YAML. The machine described on the card is this one: publish where it trained.

    :param scores: measured cost ratios to LQR (see :func:`record_scores`), or None (not yet).
    :param replace: replace an agent of the same name (else refused).
    :raises FileNotFoundError: ``run`` is not a run folder.
    :raises ValueError: the run is not complete, its agent does not load, or ``scores`` are
        malformed, before anything is written.
    :raises FileExistsError: the zoo holds that agent already and ``replace`` is False.
    """
    run, zoo = Path(run), _zoo(zoo)
    config = read_config(run)
    if config.get("status") != COMPLETE:
        raise ValueError(f"{run} is not a complete run (its config.json says "
                         f"{config.get('status')!r}): finish it first (marine train --resume "
                         f"{run}), then publish it")
    saved = find_agent(run / "model.zip")  # loads it and its statistics: damage found here
    clean_scores = _checked_scores(scores or {})
    kind, env = kind_of(config), config["env_id"].split("/")[-1]
    target = zoo / env / kind
    if target.exists() and not replace:
        raise FileExistsError(f"the zoo holds {_name(config['env_id'], kind)} already "
                              f"({target}): pass replace=True to replace it")
    staging = zoo / env / f".{kind}.publishing"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    try:
        shutil.copyfile(saved.model, staging / "model.zip")
        if saved.vecnormalize is not None:
            shutil.copyfile(saved.vecnormalize, staging / "vecnormalize.pkl")
        shipped = {**config, "hyperparams_file": _shown(zoo / env / f"{kind}.yaml", zoo)}
        write_json(staging / CONFIG, shipped)
        card = _card(shipped, kind, saved.timesteps, run, clean_scores)
        write_json(staging / CARD, card)
        _swap_in(staging, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    entry = ZooEntry(_name(config["env_id"], kind), target, card)
    _write_retrain_yaml(entry, shipped, zoo)
    return entry


def _swap_in(staging: Path, target: Path) -> None:
    """Put the folder ``staging`` in place of ``target``: the old agent is removed only once
    the new one is whole."""
    old = target.with_name(f".{target.name}.old")
    shutil.rmtree(old, ignore_errors=True)
    if target.exists():
        target.rename(old)
    staging.rename(target)
    shutil.rmtree(old, ignore_errors=True)


def _shown(path: Path, zoo: Path) -> str:
    """``path`` relative to the folder holding the package (``agents/zoo/...``): no trace of
    this machine's folders."""
    return path.relative_to(zoo.parent.parent).as_posix()


def _card(config: Mapping[str, Any], kind: str, model_timesteps: int | None, run: Path,
          scores: Mapping[str, Any]) -> dict[str, Any]:
    """``card.json`` of the agent trained by the run ``config`` describes."""
    wall = float(config.get("wall_seconds", 0.0))
    trained = datetime.datetime.fromtimestamp((run / "model.zip").stat().st_mtime,
                                              datetime.UTC)
    return {
        "name": _name(config["env_id"], kind), "env_id": config["env_id"], "kind": kind,
        "algo": config["algo"], "estimator": config["estimator"], "seed": config["seed"],
        "timesteps": int(config["timesteps"]), "model_timesteps": model_timesteps,
        "wall_seconds": wall,
        "steps_per_second": int(config["timesteps"]) / wall if wall > 0 else None,
        "machine": _machine(), "trained": trained.isoformat(timespec="minutes"),
        "versions": _versions(), "licence": "the project's (LICENSE)", "scores": dict(scores),
    }


def _machine() -> dict[str, Any]:
    """This machine, as a card describes the one that trained the agent."""
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return {"platform": platform.platform(), "machine": platform.machine(),
            "cpu_count": os.cpu_count(), "cpus_usable": usable,
            "python": platform.python_version()}


def _versions() -> dict[str, str]:
    """The versions that saved the agent (a model file may not load in much older ones)."""
    import stable_baselines3
    import torch

    from marine_envs import __version__

    return {"marine_envs": __version__, "stable_baselines3": stable_baselines3.__version__,
            "torch": torch.__version__}


# -- scores ---------------------------------------------------------------------------------------

def record_scores(name: str, scores: Mapping[str, Any], zoo: Path | None = None) -> ZooEntry:
    """Write measured scores onto the card of the shipped agent ``name`` (and the header of its
    re-train YAML), replacing the score sets given and keeping the others.

    :param scores: ``{"tuning": {...}, "held_out": {...}}`` (either or both), each with
        ``seeds`` (the evaluation seeds) and ``cost_ratio`` (the agent's mean cost over LQR's
        behind the same estimator on them), optionally ``cost``, ``lqr_cost``, ``failed``,
        ``lqr_failed``, ``measured``, ``note``.
    :raises ValueError: no such agent, or malformed scores (naming the entry), before any write.
    """
    path, zoo = path_of(name, zoo), _zoo(zoo)
    clean = _checked_scores(scores)
    card = _read_card(path / CARD)
    card["scores"] = {**card.get("scores", {}), **clean}
    write_json(path / CARD, card)
    entry = ZooEntry(name, path, card)
    _write_retrain_yaml(entry, read_config(path), zoo)
    return entry


def _checked_scores(scores: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """``scores`` checked (see :func:`record_scores`), as plain dicts and lists.

    :raises ValueError: the first unknown or malformed entry, named.
    """
    if not isinstance(scores, Mapping):
        raise ValueError(f"scores={scores!r} is invalid: a mapping of {' and/or '.join(SCORE_SETS)}"
                         " to their scores")
    clean = {}
    for part, values in scores.items():
        if part not in SCORE_SETS:
            raise ValueError(f"scores: unknown set {part!r}: one of {', '.join(SCORE_SETS)}")
        if not isinstance(values, Mapping):
            raise ValueError(f"scores: {part}: must map {', '.join(_SCORE_KEYS)} to values")
        missing = [key for key in _SCORE_REQUIRED if key not in values]
        if missing:
            raise ValueError(f"scores: {part}: missing {', '.join(missing)}")
        for key, value in values.items():
            if key not in _SCORE_KEYS:
                raise ValueError(f"scores: {part}: unknown entry {key!r}: one of "
                                 f"{', '.join(_SCORE_KEYS)}")
            if not _valid_score(key, value):
                raise ValueError(f"scores: {part}: {key}={value!r} is invalid: "
                                 f"{_SCORE_KEYS[key]}")
        clean[part] = {key: list(value) if key == "seeds" else value
                       for key, value in values.items()}
    return clean


def _valid_score(key: str, value: Any) -> bool:
    def number(v: Any) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)

    def count(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and v >= 0

    if key == "seeds":
        return isinstance(value, Sequence) and not isinstance(value, str) and len(value) > 0 \
            and all(count(seed) for seed in value) and len(set(value)) == len(value)
    if key == "cost_ratio":
        return number(value) and value > 0
    if key in ("cost", "lqr_cost"):
        return number(value) and value >= 0
    if key in ("failed", "lqr_failed"):
        return count(value)
    return isinstance(value, str)


# -- the re-train YAML ------------------------------------------------------------------------

def _write_retrain_yaml(entry: ZooEntry, config: Mapping[str, Any], zoo: Path) -> None:
    """``{Env}-v0/{kind}.yaml`` beside the agent's folder: the run's full settings under its env
    id (the hyperparameter file's format) and an ``agent:`` section with what ``marine train``
    takes on its command line, under a header saying how it was trained and what it scored."""
    import yaml  # here: only writing the YAML needs PyYAML

    settings = {"n_timesteps": int(config.get("target_timesteps", config["timesteps"])),
                "n_envs": int(config["n_envs"]), **config["hyperparams"]}
    agent = {"env_id": config["env_id"], "algo": config["algo"],
             "estimator": config["estimator"], "seed": int(config["seed"]),
             "out": f"runs/zoo/{entry.path.parent.name}/{entry.kind}"}
    if config.get("backend", "native") != "native":
        agent["backend"] = config["backend"]
    if config.get("max_episode_steps") is not None:
        agent["max_episode_steps"] = int(config["max_episode_steps"])
    document = {config["env_id"]: {config["algo"]: settings}, AGENT_SECTION: agent}
    path = entry.path.with_suffix(".yaml")
    write_text(path, _header(entry, _shown(path, zoo)) + "\n"
               + yaml.safe_dump(document, sort_keys=False, width=100,
                                default_flow_style=None))  # [64, 64] as in hyperparams.yaml


def _header(entry: ZooEntry, shown: str) -> str:
    """The YAML's comment: what it is, how to re-train, how it was trained, what it scored."""
    card = entry.card
    wall, rate = card.get("wall_seconds") or 0.0, card.get("steps_per_second")
    machine = card.get("machine", {})
    lines = [
        f"{entry.name}: the settings that trained the agent shipped in {shown[:-5]}/.",
        f"Re-train it: marine train --config {shown}",
        "(the agent: section gives the environment, algorithm, estimator, seed and --out; the",
        "command line overrides them, e.g. --out DIR --timesteps N).",
        f"Trained: {card.get('algo')} behind {card.get('estimator')}, seed {card.get('seed')}, "
        f"{card.get('timesteps')} steps in {format_duration(wall)}"
        + (f" ({rate:.0f} steps/s)" if rate else "") + f", {card.get('trained', '?')},",
        f"  on {machine.get('platform', '?')} with {machine.get('cpu_count', '?')} CPUs.",
    ]
    scores = card.get("scores") or {}
    if not scores:
        lines.append("Cost / LQR's behind the same estimator: not measured yet.")
    for part in SCORE_SETS:
        if part in scores:
            score = scores[part]
            failed = f", {score['failed']} failed" if "failed" in score else ""
            lines.append(f"Cost / LQR's behind the same estimator, {part.replace('_', '-')} "
                         f"seeds {format_seeds(score['seeds'])}: {score['cost_ratio']:.3g}"
                         f"{failed}.")
    return "".join(f"# {line}\n" for line in lines)


def format_duration(seconds: float) -> str:
    """``seconds`` as ``42 s``, ``12.5 min`` or ``2.10 h``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    return f"{seconds / 60:.1f} min" if seconds < 7200 else f"{seconds / 3600:.2f} h"


def format_seeds(seeds: Sequence[int]) -> str:
    """``1000-1009`` for consecutive seeds, else ``3, 7, 12``."""
    seeds = list(seeds)
    if len(seeds) > 2 and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}-{seeds[-1]}"
    return ", ".join(str(seed) for seed in seeds)
