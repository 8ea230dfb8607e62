"""``marine bench``: which estimator helps which controller how much, on every vehicle.

A grid of vehicles x estimators x sea states x sensor degradations x controllers x seeds. Each
cell (all but the seed) runs its seeds as one batch of the native vector environment through
:func:`agents.evaluation.evaluate`, so every controller is scored on the same episodes and the
same quadratic cost. SB3 controllers are trained first (one agent per vehicle, estimator and
algorithm, on the moderate sea and the default sensors) or loaded from ``marine train``
directories. Cells run in local processes or as Ray tasks; finished cells are kept in
``rows.csv`` and not run again.

Outputs in ``--out``: ``rows.csv`` (and ``rows.parquet`` with pyarrow), ``summary.md`` (cost
mean ± std per cell, and the ordering true <= KF <= raw), ``cost_by_estimator.png``,
``degradation.png`` (when a degradation has several levels); ``--report DIR`` puts them in one
HTML page.
"""

from __future__ import annotations

import base64
import dataclasses
import itertools
import json
import math
import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pandas as pd

from .evaluation import ESTIMATORS, ORACLE, RAW

VEHICLES = {"usv": "marine_envs/USV-v0", "hydrofoil": "marine_envs/Hydrofoil-v0",
            "rov": "marine_envs/ROV-v0", "dp": "marine_envs/DPVessel-v0",
            "hovercraft": "marine_envs/Hovercraft-v0"}
#: Sea states (and the ROV's current, the hovercraft's wind) as environment arguments;
#: "moderate" is each environment's default.
SEAS: dict[str, dict[str, dict[str, Any]]] = {
    "calm": {"usv": {"hs": 1.0}, "hydrofoil": {"hs": 0.10},
             "rov": {"current": (0.05, 0.0, 0.0), "current_std": 0.02},
             "dp": {"params": {"sigma_eta": [0.5, 0.5, math.radians(1.0)],
                               "sigma_b": [2.5e4, 2.5e4, 5e5]}},
             "hovercraft": {"wind_speed": 2.0, "wind_gust": 0.5}},
    "moderate": {v: {} for v in VEHICLES},
    "rough": {"usv": {"hs": 3.5, "tp": 9.0}, "hydrofoil": {"hs": 0.30},
              "rov": {"current": (0.3, 0.0, 0.0), "current_std": 0.1},
              "dp": {"params": {"sigma_eta": [2.0, 2.0, math.radians(4.0)],
                                "sigma_b": [1e5, 1e5, 2e6]}},
              "hovercraft": {"wind_speed": 10.0, "wind_gust": 2.0}},
}
#: Sensor degradations: ``default`` or ``kind=level`` joined by ``+``. ``noise=k``: k times
#: each channel's default noise std; ``quant=k``: a quantization step of k default stds;
#: ``dropout=p``: each sample lost with probability p; ``delay=n``: n control periods late.
DEGRADATIONS = ("noise", "quant", "dropout", "delay")
SB3_ALGOS = ("ppo", "sac", "td3", "a2c")
CONTROLLERS = ("lqr", "nominal", *SB3_ALGOS)  # and "sb3:DIR" for a saved agent
KEYS = ("vehicle", "estimator", "controller", "sea", "sensor")
TRAINING_SEED = 10_000  # agents never train on the evaluation seeds 0, 1, ...


@dataclasses.dataclass(frozen=True)
class Grid:
    """What ``marine bench`` runs.

    :param seeds: episodes per cell (seeds ``0 .. seeds - 1``).
    :param seconds: episode length, s (None: each environment's own).
    :param timesteps: training budget of each SB3 agent the grid trains, environment steps.
    """

    vehicles: tuple[str, ...] = tuple(VEHICLES)
    estimators: tuple[str, ...] = (ORACLE, RAW, "kf", "akf", "ekf")
    controllers: tuple[str, ...] = ("lqr",)
    seas: tuple[str, ...] = ("moderate",)
    sensors: tuple[str, ...] = ("default",)
    seeds: int = 5
    seconds: float | None = None
    timesteps: int = 100_000

    @classmethod
    def quick(cls) -> Grid:
        """All five vehicles, four estimators, LQR and PPO, the default sensors and 32 times
        their noise (where filtering matters), three 60-s episodes: minutes on 2 cores."""
        return cls(estimators=(ORACLE, RAW, "kf", "akf"), controllers=("lqr", "ppo"),
                   sensors=("default", "noise=32"), seeds=3, seconds=60.0, timesteps=20_000)

    def __post_init__(self) -> None:
        for name, values, known in (("vehicle", self.vehicles, VEHICLES),
                                    ("sea", self.seas, SEAS),
                                    ("estimator", self.estimators, (ORACLE, RAW, *ESTIMATORS))):
            unknown = [v for v in values if v not in known]
            if unknown:
                raise ValueError(f"unknown {name}(s) {unknown}: choose from {', '.join(known)}")
        for controller in self.controllers:
            if controller not in CONTROLLERS and not controller.startswith("sb3:"):
                raise ValueError(f"unknown controller {controller!r}: one of "
                                 f"{', '.join(CONTROLLERS)} or sb3:DIR (a 'marine train' output)")
        for sensor in self.sensors:
            parse_sensor(sensor)
        if not (isinstance(self.seeds, int) and self.seeds >= 1):
            raise ValueError(f"seeds={self.seeds!r} is invalid: an integer >= 1")
        if self.seconds is not None and not (math.isfinite(self.seconds) and self.seconds > 0):
            raise ValueError(f"seconds={self.seconds!r} is invalid: a positive duration in s")
        if not (isinstance(self.timesteps, int) and self.timesteps >= 1):
            raise ValueError(f"timesteps={self.timesteps!r} is invalid: an integer >= 1")

    def cells(self) -> list[dict[str, str]]:
        return [dict(zip(KEYS, values, strict=True))
                for values in itertools.product(self.vehicles, self.estimators, self.controllers,
                                                self.seas, self.sensors)]

    def settings(self) -> dict[str, Any]:
        """What makes rows comparable across runs (a resumed grid must match)."""
        return {"seeds": self.seeds, "seconds": self.seconds, "timesteps": self.timesteps}


def parse_sensor(spec: str) -> dict[str, float]:
    """``"noise=4+dropout=0.1"`` as ``{"noise": 4.0, "dropout": 0.1}``; ``"default"`` as {}.

    :raises ValueError: an unknown kind or a bad level, naming it.
    """
    if spec == "default":
        return {}
    out: dict[str, float] = {}
    for part in spec.split("+"):
        kind, _, level = part.partition("=")
        try:
            value = float(level)
        except ValueError:
            value = math.nan
        if kind not in DEGRADATIONS or not (math.isfinite(value) and value >= 0):
            raise ValueError(f"sensor degradation {part!r} is invalid: default, or kind=level "
                             f"joined by '+', kind one of {', '.join(DEGRADATIONS)} "
                             "(e.g. noise=4+dropout=0.1)")
        if kind == "dropout" and value >= 1:
            raise ValueError(f"sensor degradation {part!r} is invalid: dropout is a "
                             "probability < 1")
        out[kind] = value
    return out


def sensor_kwargs(spec: str, sensors: Any) -> dict[str, Any]:
    """The environment arguments of sensor degradation ``spec`` (see :data:`DEGRADATIONS`),
    relative to the default noise of ``sensors`` (the environment's ``SensorSuite``)."""
    from marine_envs.sensors import GaussianNoise

    levels = parse_sensor(spec)
    if not levels:
        return {}
    noise = [s.std for s in sensors.stages if isinstance(s, GaussianNoise)]
    std = noise[0] if noise else np.zeros(len(sensors.channels))
    per_channel = lambda k: {c: float(k * s) for c, s in zip(sensors.channels, std,  # noqa: E731
                                                              strict=True)}
    out: dict[str, Any] = {}
    if "noise" in levels:
        out["noise_std"] = per_channel(levels["noise"])
    if "quant" in levels:
        out["quantization"] = per_channel(levels["quant"])
    if "dropout" in levels:
        out["dropout"] = levels["dropout"]
    if "delay" in levels:
        out["delay"] = int(round(levels["delay"]))
    return out


def cell_key(cell: Mapping[str, Any]) -> tuple[str, ...]:
    return tuple(str(cell[k]) for k in KEYS)


# -- the work of one task (runs in a worker process or a Ray task) -------------------------------

def _agent_dir(out: Path, vehicle: str, estimator: str, algo: str) -> Path:
    return out / "agents" / f"{vehicle}-{estimator}-{algo}"


def train_agent(out: Path, vehicle: str, estimator: str, algo: str, timesteps: int) -> str | None:
    """Train the grid's agent into its directory; None if done, else why it cannot be (also
    written to ``untrainable.txt`` there, for the cells that wanted it)."""
    from .sb3 import train

    path = _agent_dir(out, vehicle, estimator, algo)
    try:
        # the grid's own budget, last iterate: validating on full episodes (the YAML's
        # validation_episodes) would cost more than training at a small --timesteps
        train(VEHICLES[vehicle], algo, estimator, timesteps, path, seed=TRAINING_SEED,
              progress_bar=False, hyperparams={"validation_episodes": 0})
    except (ValueError, ImportError, FloatingPointError) as error:
        path.mkdir(parents=True, exist_ok=True)
        (path / "untrainable.txt").write_text(str(error))
        return str(error)
    return None


def _saved_agent(controller: str, vehicle: str, estimator: str) -> Any:
    """The ``sb3:DIR`` agent, if it was trained on this vehicle behind this estimator."""
    from .sb3 import load_agent

    agent = load_agent(Path(controller[4:]))
    trained_on = (agent.config["env_id"], agent.config["estimator"] or RAW)
    if trained_on != (VEHICLES[vehicle], estimator):
        raise ValueError(f"{controller} was trained on {trained_on[0]} behind {trained_on[1]}")
    return agent


def run_cell(cell: Mapping[str, str], settings: Mapping[str, Any], out: str) -> list[dict]:
    """Score one cell over the grid's seeds: one row per seed, or one ``n/a`` row saying why the
    cell does not apply (e.g. LQR on sensors that are not states, seed 000's observer off the
    USV, an agent whose training failed)."""
    import torch

    from .evaluation import evaluate
    from .sb3 import load_agent

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
            policy: Any = lambda venv: load_agent(path)  # noqa: E731
        elif controller.startswith("sb3:"):
            agent = _saved_agent(controller, vehicle, estimator)
            policy = lambda venv: agent  # noqa: E731
        else:
            policy = controller
        sim = gym.make(env_id, **sea).unwrapped.sim  # its period and default sensors
        steps = None if settings["seconds"] is None else \
            max(1, round(settings["seconds"] / sim.dt))
        kwargs = {**sea, **sensor_kwargs(cell["sensor"], sim.sensors)}
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
        root = str(Path(__file__).resolve().parents[1])
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
    path.write_text(json.dumps(settings, indent=2) + "\n")


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
    """Add one cell's rows to the CSV (a new column rewrites it: metrics differ by vehicle)."""
    new = pd.DataFrame(rows)
    if not path.exists():
        new.to_csv(path, index=False)
        return
    header = pd.read_csv(path, nrows=0).columns
    if set(new.columns) <= set(header):
        new.reindex(columns=header).to_csv(path, mode="a", header=False, index=False)
    else:
        pd.concat([load_rows(path.parent), new], ignore_index=True).to_csv(path, index=False)


# -- what the rows say ---------------------------------------------------------------------------

def summary_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Cost mean and std over seeds per cell, with the number of failed episodes."""
    ok = rows[rows["status"] == "ok"]
    return (ok.groupby(list(KEYS), sort=False)
            .agg(cost=("cost", "mean"), spread=("cost", "std"), failed=("failed", "sum"),
                 episodes=("cost", "size")).reset_index())


def ordering(rows: pd.DataFrame, controller: str = "lqr") -> pd.DataFrame:
    """Per vehicle, sea and sensor: the mean costs of the true state, the KF and the raw
    sensors under ``controller``, and whether true <= KF <= raw. Fewer failed episodes rank
    first; equal costs of episodes that failed are not comparable (None), nor is a row with an
    estimator missing."""
    table = summary_table(rows)
    table = table[table["controller"] == controller]
    index = ["vehicle", "sea", "sensor"]
    wide = table.pivot_table(index=index, columns="estimator", values=["cost", "failed"],
                             sort=False)
    out = pd.DataFrame(index=wide.index)
    for name in (ORACLE, "kf", RAW):
        out[name] = wide["cost"][name] if name in wide["cost"] else np.nan
        out[f"failed_{name}"] = wide["failed"][name] if name in wide["failed"] else np.nan
    out["true<=kf<=raw"] = [_ordered(r, (ORACLE, "kf", RAW)) for r in out.to_dict("records")]
    return out.drop(columns=[f"failed_{n}" for n in (ORACLE, "kf", RAW)]).reset_index()


def _ordered(row: Mapping[str, float], names: Sequence[str]) -> bool | None:
    """Whether ``names`` are in order of (failures, cost); None if it cannot be told."""
    verdicts = []
    for a, b in zip(names, names[1:], strict=False):
        fa, fb = row[f"failed_{a}"], row[f"failed_{b}"]
        if np.isnan(row[a]) or np.isnan(row[b]):
            return None
        if fa != fb:
            verdicts.append(fa < fb)
        elif fa > 0:
            return None  # both failed as often: their truncated costs do not compare
        else:
            verdicts.append(row[a] <= row[b])
    return all(verdicts)


def _cell_text(cost: float, spread: float, failed: float, episodes: int) -> str:
    text = f"{cost:.4g} ± {0.0 if np.isnan(spread) else spread:.2g}"
    return text + (f" ({int(failed)}/{episodes} failed)" if failed else "")


COST_NOTE = ("Task cost: the environment's quadratic LQR cost summed over the episode (lower is "
             "better), mean ± std over seeds; n/a: the cell does not apply.")
ORDER_TITLE = "True state <= KF <= raw sensors (LQR)"


def _summary_frames(rows: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """The cost table (estimators as columns), the ordering check, the cells that do not apply."""
    table = summary_table(rows)
    table["text"] = [_cell_text(*v) for v in
                     table[["cost", "spread", "failed", "episodes"]].itertuples(index=False)]
    wide = table.pivot_table(index=["vehicle", "sea", "sensor", "controller"],
                             columns="estimator", values="text", aggfunc="first", sort=False)
    wide = wide.reset_index().fillna("n/a")
    skipped = rows[rows["status"] != "ok"].drop_duplicates(subset=list(KEYS))
    reasons = [f"{' / '.join(str(r[k]) for k in KEYS)}: {r['status'][5:]}"
               for r in skipped.to_dict("records")]
    return wide, ordering(rows), reasons


def _markdown_table(frame: pd.DataFrame) -> str:
    def text(v: Any) -> str:
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(map(str, frame.columns)) + " |",
             "|" + "---|" * len(frame.columns)]
    lines += ["| " + " | ".join(text(v) for v in row) + " |"
              for row in frame.itertuples(index=False)]
    return "\n".join(lines)


def markdown_summary(rows: pd.DataFrame) -> str:
    """The summary page: cost by estimator (columns) per vehicle, sea, sensor and controller,
    the ordering check, and the cells that do not apply."""
    wide, order, skipped = _summary_frames(rows)
    lines = ["# Estimator benchmark", "", COST_NOTE, "", _markdown_table(wide), ""]
    if len(order):
        lines += [f"## {ORDER_TITLE}", "", _markdown_table(order), ""]
    if skipped:
        lines += ["## Cells that do not apply", "", *[f"- {line}" for line in skipped], ""]
    return "\n".join(lines)


def plot_costs(rows: pd.DataFrame, path: Path) -> Path:
    """Cost by estimator per vehicle (bars per controller, std as error bars; log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = summary_table(rows)
    table = table[(table["sea"] == table["sea"].iloc[0]) &
                  (table["sensor"] == table["sensor"].iloc[0])]
    vehicles = list(dict.fromkeys(table["vehicle"]))
    fig, axes = plt.subplots(1, len(vehicles), figsize=(3.2 * len(vehicles) + 1, 3.6),
                             squeeze=False)
    for ax, vehicle in zip(axes[0], vehicles, strict=True):
        part = table[table["vehicle"] == vehicle]
        estimators = list(dict.fromkeys(part["estimator"]))
        controllers = list(dict.fromkeys(part["controller"]))
        width = 0.8 / len(controllers)
        for j, controller in enumerate(controllers):
            sub = part[part["controller"] == controller].set_index("estimator")
            x = [i + j * width for i, e in enumerate(estimators) if e in sub.index]
            got = [e for e in estimators if e in sub.index]
            ax.bar(x, sub.loc[got, "cost"], width, yerr=sub.loc[got, "spread"].fillna(0),
                   label=controller, capsize=2)
        ax.set_xticks([i + 0.4 - width / 2 for i in range(len(estimators))], estimators,
                      rotation=45)
        ax.set_yscale("log")
        ax.set_title(vehicle)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel("task cost")
    axes[0][-1].legend(fontsize=8)
    fig.suptitle(f"Cost by estimator (sea {table['sea'].iloc[0]}, sensors "
                 f"{table['sensor'].iloc[0]})")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_degradation(rows: pd.DataFrame, path: Path) -> Path | None:
    """Cost against the level of each single degradation (``default`` is level 1 of noise and
    0 of the others), per vehicle, a line per estimator under LQR; None with fewer than two
    levels of any kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = summary_table(rows)
    controller = "lqr" if (table["controller"] == "lqr").any() else table["controller"].iloc[0]
    table = table[table["controller"] == controller]
    colours = {e: f"C{i}" for i, e in enumerate(dict.fromkeys(table["estimator"]))}
    levels = {s: parse_sensor(s) for s in table["sensor"].unique()}
    kinds = [k for k in DEGRADATIONS
             if len({lv.get(k, 1.0 if k == "noise" else 0.0)
                     for lv in levels.values() if set(lv) <= {k}}) >= 2]
    if not kinds:
        return None
    vehicles = list(dict.fromkeys(table["vehicle"]))
    fig, axes = plt.subplots(len(kinds), len(vehicles), squeeze=False,
                             figsize=(3.2 * len(vehicles) + 1, 3.0 * len(kinds)))
    for row, kind in enumerate(kinds):
        for ax, vehicle in zip(axes[row], vehicles, strict=True):
            part = table[(table["vehicle"] == vehicle)]
            for estimator in dict.fromkeys(part["estimator"]):
                sub = part[part["estimator"] == estimator]
                points = sorted((levels[s].get(kind, 1.0 if kind == "noise" else 0.0), c)
                                for s, c in zip(sub["sensor"], sub["cost"], strict=True)
                                if set(levels[s]) <= {kind})
                if len(points) >= 2:
                    ax.plot(*zip(*points, strict=True), marker="o", label=estimator,
                            color=colours[estimator])
            ax.set_yscale("log")
            ax.set_xlabel(kind)
            ax.set_title(vehicle)
            ax.grid(alpha=0.3)
        axes[row][0].set_ylabel("task cost")
    handles = {line.get_label(): line for ax in axes.flat for line in ax.get_lines()}
    fig.legend(handles.values(), handles.keys(), loc="upper right", fontsize=8)
    fig.suptitle(f"Degradation curves ({controller})")
    fig.tight_layout(rect=(0, 0, 0.92, 1))
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def write_outputs(rows: pd.DataFrame, out: Path) -> list[Path]:
    """``summary.md``, the figures and (with pyarrow) ``rows.parquet`` into ``out``."""
    written = [out / ROWS]
    try:
        rows.to_parquet(out / "rows.parquet", index=False)
        written.append(out / "rows.parquet")
    except ImportError:
        pass  # Parquet is optional: pip install 'marine-envs[parquet]'
    (out / "summary.md").write_text(markdown_summary(rows))
    written.append(out / "summary.md")
    if (rows["status"] == "ok").any():
        written.append(plot_costs(rows, out / "cost_by_estimator.png"))
        degradation = plot_degradation(rows, out / "degradation.png")
        if degradation is not None:
            written.append(degradation)
    return written


def write_report(rows: pd.DataFrame, out: Path, report: Path, grid: Grid) -> Path:
    """One self-contained HTML page (``report/index.html``): the grid, the cost table, the
    ordering check, the cells that do not apply and the figures, inlined."""
    report = Path(report)
    report.mkdir(parents=True, exist_ok=True)
    wide, order, skipped = _summary_frames(rows)
    parts = ["<!doctype html><meta charset='utf-8'><title>marine bench</title>",
             "<style>body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
             "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}</style>",
             "<h1>Estimator benchmark</h1>",
             f"<p>Grid: {_html_escape(json.dumps(dataclasses.asdict(grid)))}</p>",
             f"<p>{COST_NOTE}</p>", wide.to_html(index=False)]
    if len(order):
        parts += [f"<h2>{ORDER_TITLE}</h2>", order.to_html(index=False, float_format="%.4g")]
    if skipped:
        parts += ["<h2>Cells that do not apply</h2><ul>",
                  *[f"<li>{_html_escape(line)}</li>" for line in skipped], "</ul>"]
    for name in ("cost_by_estimator.png", "degradation.png"):
        if (out / name).exists():
            data = base64.b64encode((out / name).read_bytes()).decode()
            parts.append(f"<p><img src='data:image/png;base64,{data}' alt='{name}'></p>")
    page = report / "index.html"
    page.write_text("\n".join(parts) + "\n")
    return page


def _html_escape(text: str) -> str:
    import html

    return html.escape(text)
