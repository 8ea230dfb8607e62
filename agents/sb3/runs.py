"""A training run's folder: what :func:`~agents.sb3.training.train` writes into it
(:data:`OWNED`: ``config.json``, the agents and their normalisation statistics, checkpoints),
each file written whole; the lock that keeps one writer a folder (:func:`run_lock`); and the
saved agents in it, found and checked before use (:func:`find_agent`, :func:`latest`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import errno
import fcntl
import json
import os
import pickle
import re
import shutil
import time
import warnings
import zipfile
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.save_util import load_from_zip_file

from marine_envs.files import WriteError, atomic_path, write_json

from .hyperparams import COMPLETE, INTERRUPTED, RUNNING, _one_line

# -- the run folder ---------------------------------------------------------------------------

CONFIG = "config.json"
CHECKPOINTS = "checkpoints"
#: What :func:`~agents.sb3.training.train` writes into its folder; ``force`` clears exactly these.
OWNED = ("model.zip", "last_model.zip", "vecnormalize.pkl", "last_vecnormalize.pkl", CONFIG,
         CHECKPOINTS, "tb")
_CHECKPOINT = re.compile(r"model_(\d+)_steps\.zip")

def _save_agent(model: BaseAlgorithm, path: Path, statistics: Path) -> None:
    """Save ``model`` to ``path`` and its normalisation statistics (if it has any) to
    ``statistics``, each written whole (:func:`marine_envs.files.atomic_path`): both are
    written before either replaces its file, so a full disk changes neither, and the statistics
    land first, so a model file is never without its own.

    :raises marine_envs.files.WriteError: a file could not be written (named).
    """
    normalizer = model.get_vec_normalize_env()
    try:
        with atomic_path(path) as model_file:
            with open(model_file, "wb") as f:  # closed on an error too (SB3 leaves its open)
                model.save(f)
            if normalizer is not None:
                with atomic_path(statistics) as statistics_file:
                    normalizer.save(str(statistics_file))
    except WriteError as error:  # the statistics' error, wrapped by the model's atomic_path
        while isinstance(error.__cause__, WriteError):
            error = error.__cause__
        raise error from None


def _write_config(out: Path, config: Mapping[str, Any]) -> None:
    """``config.json``, replaced whole (a reader never sees half of it)."""
    write_json(out / CONFIG, config)


def read_config(run: Path) -> dict[str, Any]:
    """The ``config.json`` of the run folder ``run``.

    :raises FileNotFoundError: no such folder or no config.json in it.
    :raises ValueError: it is not a JSON object of a run's settings.
    """
    path = Path(run) / CONFIG
    if not path.is_file():
        raise FileNotFoundError(f"{run} is not a 'marine train' folder: no {CONFIG} in it")
    try:
        config = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: invalid JSON: {error}") from None
    missing = [k for k in ("env_id", "algo", "hyperparams") if k not in (config or {})]
    if not isinstance(config, dict) or missing:
        raise ValueError(f"{path} is not a 'marine train' config: missing {missing}")
    return config


def existing_run(out: Path) -> list[str]:
    """What of a run (:data:`OWNED`) is in ``out`` already."""
    return [name for name in OWNED if (Path(out) / name).exists()]


def clear_run(out: Path) -> None:
    """Remove what :func:`~agents.sb3.training.train` wrote into ``out`` (:data:`OWNED`, and the
    temporary files of its writes that a kill cut short), and nothing else."""
    for name in OWNED:
        path = Path(out) / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
    for temporary in Path(out).glob(".*.part*"):  # marine_envs.files.atomic_path's
        if any(temporary.name.startswith(f".{name}.") for name in OWNED):
            temporary.unlink()


# -- one writer a run folder ----------------------------------------------------------------

#: The lock file of a run folder: locked by the training that writes the folder, holding its pid.
LOCK = ".lock"


class RunInUse(BlockingIOError):
    """Another training is writing the run folder: ``folder``, locked by process ``pid`` (None
    when it cannot be read)."""

    def __init__(self, folder: Path, pid: int | None) -> None:
        holder = "another process" if pid is None else f"pid {pid}"
        super().__init__(errno.EWOULDBLOCK, f"{folder} is being written by another training "
                         f"({holder}): wait for it to end, or train into another folder")
        self.folder, self.pid = folder, pid

    def __str__(self) -> str:
        return str(self.strerror)


@contextlib.contextmanager
def run_lock(out: Path) -> Iterator[None]:
    """Hold the lock of the run folder ``out`` (created if need be) for the block, so that
    two trainings (new, resumed or forced) never write into one folder. The lock is an
    ``flock`` of ``out/.lock``, which holds the writer's pid; the kernel drops it when the
    process ends, however it ends (SIGKILL too), so a dead run never leaves its folder locked.
    A folder made here is removed again if it holds none of a run when the block ends (a
    setting refused when the environments are built).

    :raises RunInUse: another process holds the lock.
    """
    out = Path(out)
    made = [folder for folder in (out, *out.parents) if not folder.exists()]  # deepest first
    out.mkdir(parents=True, exist_ok=True)
    lock = _lock(out / LOCK)
    try:
        yield
    finally:
        if made and not existing_run(out):
            (out / LOCK).unlink()  # while locked: see _lock
            with contextlib.suppress(OSError):  # one that something else wrote into stays
                for folder in made:
                    folder.rmdir()
        os.close(lock)  # releases the lock


def _lock(path: Path) -> int:
    """Lock ``path`` (created if need be) and write this process's pid into it; the returned
    descriptor holds the lock until it is closed.

    :raises RunInUse: another process holds it.
    """
    while True:
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        if not _flock(descriptor, fcntl.LOCK_EX, patience=0.5):  # a check_not_in_use's moment
            os.close(descriptor)
            raise RunInUse(path.parent, _holder(path))
        if _same_file(descriptor, path):
            break
        os.close(descriptor)  # removed since it was opened (a failed start's cleanup): anew
    try:
        os.ftruncate(descriptor, 0)
        os.write(descriptor, f"{os.getpid()}\n".encode())
    except OSError as error:
        os.close(descriptor)
        raise WriteError(error.errno or errno.EIO, f"cannot write {path}: {error.strerror}",
                         str(path)) from error
    return descriptor


def check_not_in_use(out: Path) -> None:
    """Refuse the run folder ``out`` if a training is writing it, before any work (and without
    creating anything: the training itself takes the lock, :func:`run_lock`).

    :raises RunInUse: a training holds its lock.
    """
    path = Path(out) / LOCK
    try:
        descriptor = os.open(path, os.O_RDONLY)
    except (FileNotFoundError, NotADirectoryError):
        return  # no lock file: never trained into
    try:
        if not _flock(descriptor, fcntl.LOCK_SH, patience=0.0):
            raise RunInUse(Path(out), _holder(path))
    finally:
        os.close(descriptor)  # releases the shared lock at once


def _flock(descriptor: int, operation: int, patience: float) -> bool:
    """Lock ``descriptor`` (``fcntl.LOCK_EX`` or ``LOCK_SH``) without blocking, trying again
    for ``patience`` seconds; whether it is locked."""
    deadline = time.monotonic() + patience
    while True:
        try:
            fcntl.flock(descriptor, operation | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)


def _same_file(descriptor: int, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(descriptor), os.stat(path))
    except FileNotFoundError:
        return False


def _holder(path: Path) -> int | None:
    """The pid in the lock file ``path``, None if it holds none."""
    for _ in range(100):  # the holder writes it right after locking: give it a moment
        try:
            text = path.read_text().strip()
        except OSError:
            return None
        if text:
            return int(text) if text.isdigit() else None
        time.sleep(0.01)
    return None


@dataclasses.dataclass(frozen=True)
class Saved:
    """A saved agent: its ``model`` zip, the ``vecnormalize`` statistics saved with it (None
    if there are none), the run folder whose ``config.json`` describes it and its step
    count (None if unknown)."""

    model: Path
    vecnormalize: Path | None
    run: Path
    timesteps: int | None


class FallbackWarning(UserWarning):
    """The agent asked for cannot be used (a run killed before saving, a truncated or corrupt
    file): an earlier one is used instead; the message says which and why."""


def _statistics_of(model: Path) -> Path:
    """Where :func:`~agents.sb3.training.train` saves the normalisation statistics that go with
    ``model``."""
    found = _CHECKPOINT.fullmatch(model.name)
    if found:
        return model.with_name(f"model_vecnormalize_{found[1]}_steps.pkl")
    return model.with_name(model.name.replace("model.zip", "vecnormalize.pkl"))


def _saved(model: Path, run: Path, config: Mapping[str, Any], steps: int | None) -> Saved:
    """``model`` with its statistics, checked against the run's settings and loaded once, so
    that a truncated or corrupt file is found here rather than halfway through a command.

    :raises ValueError: a file is missing or cannot be loaded (saying which, and why).
    """
    statistics = _statistics_of(model)
    if config["hyperparams"].get("normalize") and not statistics.exists():
        raise ValueError(f"{model} was trained on normalised observations but {statistics.name} "
                         "is missing beside it")
    for path in (model, statistics) if statistics.exists() else (model,):
        why = _unreadable(path)
        if why is not None:
            raise ValueError(f"{path} is unreadable ({why})")
    return Saved(model, statistics if statistics.exists() else None, run, steps)


def _unreadable(path: Path) -> str | None:
    """Why the saved model (``.zip``) or statistics (``.pkl``) ``path`` cannot be loaded; None
    if it can."""
    try:
        if path.suffix != ".zip":
            with open(path, "rb") as f:
                pickle.load(f)
            return None
        with zipfile.ZipFile(path) as archive:
            corrupt = archive.testzip()  # every member against its checksum
        if corrupt is not None:
            return f"{corrupt} in it is corrupt"
        data, params, _ = load_from_zip_file(path, device="cpu", print_system_info=False)
        if data is None or "policy" not in params:  # e.g. cut short: a zip inside it is found
            return "not a whole Stable-Baselines3 model: no " + \
                ("data" if data is None else "policy") + " in it"
        return None
    except Exception as error:  # whatever a damaged file raises (zip, torch, pickle) says why
        return _one_line(error) or type(error).__name__


def _first_loadable(run: Path, config: Mapping[str, Any],
                    candidates: Sequence[tuple[Path, int | None]], reasons: list[str]) -> Saved:
    """The first of ``candidates`` (model file, steps) that loads (:func:`_saved`); when it is
    not the agent asked for, a :class:`FallbackWarning` says which it is and why (``reasons``,
    and why each candidate before it was passed over).

    :raises ValueError: none loads (saying why each did not).
    """
    for model, steps in candidates:
        try:
            saved = _saved(model, run, config, steps)
        except ValueError as error:
            reasons.append(str(error))
            continue
        if reasons:
            what = "checkpoint " if model.parent.name == CHECKPOINTS else ""
            count = "" if steps is None else f" ({steps} steps)"
            warnings.warn(f"using {what}{model}{count}: {'; '.join(reasons)}", FallbackWarning,
                          stacklevel=3)
        return saved
    if not reasons:
        raise ValueError(f"{run} holds no model.zip and no checkpoint yet")
    raise ValueError(f"{run} holds no loadable agent: {'; '.join(reasons)}")


def checkpoints(run: Path) -> list[tuple[int, Path]]:
    """The run's checkpoints as ``(steps, path)``, oldest first."""
    folder = Path(run) / CHECKPOINTS
    found = [(int(m[1]), p) for p in folder.glob("model_*_steps.zip")
             if (m := _CHECKPOINT.fullmatch(p.name))] if folder.is_dir() else []
    return sorted(found)


def find_agent(path: Path) -> Saved:
    """The agent that ``path`` names: a run folder (its ``model.zip``, else its latest
    checkpoint that loads: a run stopped before saving, or whose file is truncated or
    corrupt, with a :class:`FallbackWarning` saying so), or a model file (``model.zip``,
    ``last_model.zip`` or ``checkpoints/model_<N>_steps.zip``) of a run folder.

    :raises FileNotFoundError: no such file or folder.
    :raises ValueError: a file that is not a saved model of a run or does not load, or a run
        without any agent that loads.
    """
    path = Path(path)
    if path.is_dir():
        config = read_config(path)
        final = path / "model.zip"
        found = [(p, steps) for steps, p in reversed(checkpoints(path))]
        if final.exists():
            return _first_loadable(path, config, [(final, _final_steps(config, final.name)),
                                                  *found], [])
        killed = " (its training is running, or was stopped before saving)" \
            if config.get("status") == RUNNING else ""
        return _first_loadable(path, config, found,
                               [f"{path} has no model.zip{killed}"] if found else [])
    if not path.exists():
        raise FileNotFoundError(f"no such run folder or model file: {path}")
    run = path.parent.parent if path.parent.name == CHECKPOINTS else path.parent
    if path.suffix != ".zip" or not (run / CONFIG).is_file():
        raise ValueError(f"{path} is not a model saved by 'marine train': give its run folder, "
                         "its model.zip or a checkpoints/model_<N>_steps.zip")
    config = read_config(run)
    found = _CHECKPOINT.fullmatch(path.name)
    return _saved(path, run, config, int(found[1]) if found else _final_steps(config, path.name))


def _final_steps(config: Mapping[str, Any], name: str) -> int | None:
    """Steps of the run's final ``model.zip`` or ``last_model.zip`` (None: not known)."""
    if config.get("status", COMPLETE) == RUNNING:
        return None
    if name == "model.zip" and config.get("validation"):
        selected = config["validation"].get("selected")
        return None if selected is None else int(selected["timesteps"])
    return int(config["timesteps"])


def latest(run: Path) -> Saved:
    """Where :func:`~agents.sb3.training.resume` continues ``run``: the last agent it saved that
    loads, by step count (the final or interrupted one, or a later checkpoint of a run that was
    killed); a :class:`FallbackWarning` says when that is not the run's final agent, and why.

    :raises FileNotFoundError: ``run`` is not a run folder.
    :raises ValueError: nothing saved, or nothing that loads.
    """
    run = Path(run)
    config = read_config(run)
    candidates = [(steps, 1, path) for steps, path in checkpoints(run)]
    last = run / ("last_model.zip" if config.get("validation") else "model.zip")
    ended = config.get("status", COMPLETE) in (INTERRUPTED, COMPLETE)
    if ended and last.exists():  # else older than the checkpoints, if there at all
        candidates.append((int(config["timesteps"]), 2, last))  # the same steps: it wins
    if not candidates:
        raise ValueError(f"{run} holds no saved agent to resume from (no model, no checkpoint)")
    reasons = [] if ended else [f"{run} was not saved at its end (its config.json says "
                                f"{RUNNING!r}: it was killed, or stopped by an error)"]
    return _first_loadable(run, config, [(path, steps) for steps, _, path in
                                         sorted(candidates, reverse=True)], reasons)


