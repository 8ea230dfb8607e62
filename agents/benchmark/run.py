"""Running the grid: the work of one task (training an SB3 agent, scoring a cell), the local
(process pool) and Ray backends, and :func:`run_grid` with its rows file.

SB3 controllers are trained first (one agent per vehicle, estimator and algorithm, on the
moderate sea and the default sensors) or loaded from ``marine train`` directories. Each cell runs
its seeds as one batch of the native vector environment through
:func:`agents.evaluation.evaluate`, in local processes or as Ray tasks (which run the
module-level functions here by reference); finished cells are kept in ``rows.csv`` and not run
again.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import pandas as pd

from estimators.registry import RAW
from marine_envs.files import atomic_path, write_json, write_text

from .grid import KEYS, SB3_ALGOS, SEAS, TRAINING_SEED, VEHICLES, Grid, cell_key, sensor_kwargs

# -- the work of one task (runs in a worker process or a Ray task) -------------------------------

def _agent_dir(out: Path, vehicle: str, estimator: str, algo: str) -> Path:
    return out / "agents" / f"{vehicle}-{estimator}-{algo}"


def train_agent(out: Path, vehicle: str, estimator: str, algo: str, timesteps: int) -> str | None:
    """Train the grid's agent into its directory; None if done, else why it cannot be (also
    written to ``untrainable.txt`` there, for the cells that wanted it)."""
    from ..sb3 import train

    path = _agent_dir(out, vehicle, estimator, algo)
    try:
        # the grid's own budget, last iterate: validating on full episodes (the YAML's
        # validation_episodes) would cost more than training at a small --timesteps
        train(VEHICLES[vehicle], algo, estimator, timesteps, path, seed=TRAINING_SEED,
              progress_bar=False, hyperparams={"validation_episodes": 0})
    except (ValueError, ImportError, FloatingPointError) as error:
        path.mkdir(parents=True, exist_ok=True)
        write_text(path / "untrainable.txt", str(error))
        return str(error)
    return None


def _saved_agent(controller: str, vehicle: str, estimator: str) -> Any:
    """The ``sb3:DIR`` agent, if it was trained on this vehicle behind this estimator."""
    from ..sb3 import load_agent

    agent = load_agent(Path(controller[4:]))
    trained_on = (agent.config["env_id"], agent.config["estimator"] or RAW)
    if trained_on != (VEHICLES[vehicle], estimator):
        raise ValueError(f"{controller} was trained on {trained_on[0]} behind {trained_on[1]}")
    return agent


def run_cell(cell: Mapping[str, str], settings: Mapping[str, Any], out: str) -> list[dict]:
    """Score one cell over the grid's seeds: one row per seed, or one ``n/a`` row saying why the
    cell does not apply (e.g. LQR on sensors that are not states, the USV observer patent's
    observer off the USV, an agent whose training failed)."""
    import torch

    from ..evaluation import evaluate
    from ..sb3 import load_agent

    torch.set_num_threads(1)  # one task per core
    vehicle, controller, estimator = cell["vehicle"], cell["controller"], cell["estimator"]
    env_id = VEHICLES[vehicle]
    sea = SEAS[cell["sea"]][vehicle]
    try:
        if controller in SB3_ALGOS:
            path = _agent_dir(Path(out), vehicle, estimator, controller)
            if not (path / "model.zip").exists():
                why = path / "untrainable.txt"
                raise ValueError("its agent could not be trained: " +
                                 (why.read_text() if why.exists() else "no model.zip"))
            policy: Any = load_agent(path)  # an agent is its own factory
        elif controller.startswith("sb3:"):
            policy = _saved_agent(controller, vehicle, estimator)
        else:
            policy = controller
        system = gym.make(env_id, **sea).unwrapped.system  # its period and default sensors
        steps = None if settings["seconds"] is None else \
            max(1, round(settings["seconds"] / system.dt))
        kwargs = {**sea, **sensor_kwargs(cell["sensor"], system.sensors)}
        rows = evaluate(env_id, policy, estimator, settings["seeds"], kwargs, steps)
    except (ValueError, ImportError, FloatingPointError) as error:  # a diverged model too
        return [{**cell, "status": f"n/a: {error}"}]
    return [{**cell, "status": "ok", **row} for row in rows]


# -- backends ------------------------------------------------------------------------------------

Task = tuple[Callable[..., Any], tuple[Any, ...]]


def _call(task: Task) -> Any:
    function, args = task
    return function(*args)


def run_local(tasks: Sequence[Task], workers: int) -> Iterator[Any]:
    """Results of ``tasks`` as they finish, from ``workers`` processes (1: in this one)."""
    if workers <= 1 or len(tasks) <= 1:
        yield from map(_call, tasks)
        return
    import concurrent.futures
    import multiprocessing

    # spawn: a forked copy of a parent that has started torch's threads can deadlock
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
        futures = [pool.submit(_call, task) for task in tasks]
        for future in concurrent.futures.as_completed(futures):
            yield future.result()


def run_ray(tasks: Sequence[Task], address: str | None, num_cpus: int | None) -> Iterator[Any]:
    """Results of ``tasks`` as they finish, each a Ray task (one CPU); on the cluster at
    ``address`` (``auto``: the one this machine belongs to), or on a local Ray started here."""
    try:
        import ray
    except ImportError:
        raise ImportError("the Ray backend needs Ray: pip install 'marine-envs[ray]'") from None
    started = not ray.is_initialized()
    if started:
        # the workers import this package from the same source tree
        root = str(Path(__file__).resolve().parents[2])
        env = {"PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
        ray.init(address=address, num_cpus=None if address else num_cpus,
                 runtime_env={"env_vars": env}, include_dashboard=False,
                 log_to_driver=False, logging_level="ERROR")
    remote = ray.remote(num_cpus=1)(_call)
    try:
        pending = [remote.remote(task) for task in tasks]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        if started:
            ray.shutdown()


# -- the grid ------------------------------------------------------------------------------------

ROWS = "rows.csv"


def load_rows(out: Path) -> pd.DataFrame:
    """The rows finished so far in ``out`` (empty if none)."""
    path = out / ROWS
    if not path.exists():
        return pd.DataFrame(columns=[*KEYS, "status"])
    # the keys as written: CSV readers would take the estimator "true" for a boolean
    return pd.read_csv(path, dtype={k: str for k in (*KEYS, "status")})


def _check_settings(out: Path, grid: Grid) -> None:
    path = out / "grid.json"
    settings = grid.settings()
    if path.exists():
        before = json.loads(path.read_text())
        if before != json.loads(json.dumps(settings)):
            raise ValueError(f"{out} holds a grid run with {before}, not {settings}: resume "
                             "with the same --seeds/--seconds/--timesteps, or use another --out")
    write_json(path, settings)


def run_grid(grid: Grid, out: Path, backend: str = "local", workers: int = 2,
             address: str | None = None, progress: bool = True) -> pd.DataFrame:
    """Run the cells of ``grid`` not yet in ``out/rows.csv`` and return all its rows.

    :param backend: ``"local"`` (``workers`` processes) or ``"ray"`` (a task per cell, on the
        cluster at ``address``, or a local Ray of ``workers`` CPUs when it is None).
    """
    if backend not in ("local", "ray"):
        raise ValueError(f"backend={backend!r} is invalid: 'local' or 'ray'")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _check_settings(out, grid)
    done = {cell_key(row) for row in load_rows(out).to_dict("records")}
    todo = [c for c in grid.cells() if cell_key(c) not in done]

    def execute(tasks: Sequence[Task]) -> Iterator[Any]:
        if backend == "ray":
            return run_ray(tasks, address, workers)
        return run_local(tasks, workers)

    agents = sorted({(c["vehicle"], c["estimator"], c["controller"]) for c in todo
                     if c["controller"] in SB3_ALGOS})
    training = [(train_agent, (out, v, e, a, grid.timesteps)) for v, e, a in agents
                if not (_agent_dir(out, v, e, a) / "model.zip").exists()]
    # a failed training leaves its reason for the cells that wanted the agent (run_cell)
    list(_progress(execute(training), len(training), "training agents", progress))
    settings = grid.settings()
    cells = [(run_cell, (cell, settings, str(out))) for cell in todo]
    for rows in _progress(execute(cells), len(cells), "grid cells", progress):
        _append(out / ROWS, rows)
    # the grid's order, whatever order the cells finished in
    order = {cell_key(c): i for i, c in enumerate(grid.cells())}
    frame = load_rows(out)
    frame["_cell"] = [order.get(cell_key(r), -1) for r in frame.to_dict("records")]
    frame = frame[frame["_cell"] >= 0]
    by = ["_cell", "seed"] if "seed" in frame else ["_cell"]
    return frame.sort_values(by, kind="stable").drop(columns="_cell").reset_index(drop=True)


def _progress(results: Iterable[Any], total: int, what: str, show: bool) -> Iterable[Any]:
    if not show or total == 0:
        return results
    from tqdm import tqdm

    return tqdm(results, total=total, desc=what, unit="task")


def _append(path: Path, rows: list[dict]) -> None:  # path: out / ROWS
    """Add one cell's rows to the CSV (a new column rewrites it: metrics differ by vehicle),
    as a new whole file: a full disk or a kill on the way keeps the cells done before."""
    new = pd.DataFrame(rows)
    with atomic_path(path) as temporary:
        if not path.exists():
            new.to_csv(temporary, index=False)
            return
        header = pd.read_csv(path, nrows=0).columns
        if set(new.columns) <= set(header):
            shutil.copyfile(path, temporary)
            new.reindex(columns=header).to_csv(temporary, mode="a", header=False, index=False)
        else:
            pd.concat([load_rows(path.parent), new], ignore_index=True).to_csv(temporary,
                                                                             index=False)

