"""Which estimator earns its place: LQR behind each one, every vehicle, three sensor noises.

For each vehicle, the task's LQR (``agents.evaluation.evaluate``, full registered episodes)
behind the true state, the raw sensors, the white-noise Kalman filter (``kf_white``), the
filter with the disturbances' own models (``kf``: waves, current, wind, events as states of
their own, model error and prior from the env's own models; behind it LQR feeds the estimated
disturbances forward) and the adaptive filter on it (``akf``), at the default sensors and at 4
and 32 times their noise. Two seed sets: the one the filter's settings were chosen on (tuning,
1000-1005) and one they never saw (held out, 2000-2005; the acceptance is judged there):

* default sensors: LQR behind ``kf`` costs no more than behind the raw sensors; on the ROV at
  most 0.9x raw; on the DP vessel (whose raw sensors LQR cannot use) at most 1.3x the true state;
* noise x32: true <= ``kf`` <= raw where raw is defined and no episode failed.

A cell whose episodes failed shows how many (``k/6 fail``): a crash ends the cost early, so its
cost does not compare. Writes a figure of cost against the noise factor per vehicle.

With ``--agents DIR ...`` (agents saved by ``marine train`` or ``benchmarks/rl_vs_lqr.py``, e.g.
PPO behind ``kf`` and the recurrent PPO on the raw sensors), each (algorithm, estimator) of a
vehicle is a column too, "ppo on kf": the agents trained at the default sensors, scored on the
same seeds and sensors as LQR behind the estimator they were trained behind (the mean over the
agents given, their failed episodes summed).

    python benchmarks/filters.py [--vehicles USV ROV] [--sets tuning held_out]
                                 [--agents runs/rl_vs_lqr/*] [--plot docs/filters.png]
                                 [--json out.json] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from _common import REPO, Run, add_docs_option, benchmark_run, check_page_path  # noqa: E402
from tqdm import tqdm  # noqa: E402

import marine_envs  # noqa: E402, F401
from agents import sb3  # noqa: E402
from agents.benchmark.grid import sensor_kwargs  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from marine_envs.files import write_json  # noqa: E402

TITLE = "Which filter earns its place"
ABOUT = """\
The task's LQR behind each estimator, on every vehicle, at the default sensors and at 4 and 32
times their noise: the true state, the raw sensors, the white-noise Kalman filter (`kf_white`),
the Kalman filter carrying its disturbances' own models (`kf`: waves, current, wind and events
as states of their own, model error and prior from the env's own models; behind it LQR feeds
the estimated disturbances forward) and the adaptive filter on it (`akf`). Each cell is the mean
task cost of 6 full registered episodes (`agents.evaluation.evaluate`); a cell whose episodes
failed says how many (a crash ends the cost early, so its cost does not compare). The tuning
seeds (1000-1005) are the ones the filter's settings were chosen on; the held-out seeds
(2000-2005) chose nothing, and the acceptance lines are judged there. The figure plots the cost
against the sensor noise on the first seed set shown (held out when run)."""

VEHICLES = ("USV", "Hydrofoil", "ROV", "DPVessel", "Hovercraft")
ESTIMATORS = ("true", "raw", "kf_white", "kf", "akf")
SENSORS = ("default", "noise=4", "noise=32")
SEED_SETS = {"tuning": range(1000, 1006), "held_out": range(2000, 2006)}
#: default sensors: kf / raw at most this (DP vessel: kf / true)
BOUND = {"ROV": ("raw", 0.9), "DPVessel": ("true", 1.3)}


def cell(vehicle: str, estimator: str, sensors: str, seeds: range,
         agents: Sequence[sb3.Agent] = ()) -> dict[str, Any]:
    """LQR's (or the ``agents``') mean cost and failed episodes behind ``estimator``; None
    where LQR cannot read what it gives (the DP vessel's raw sensors are not its states)."""
    env_id = f"marine_envs/{vehicle}-v0"
    kwargs = sensor_kwargs(sensors, gym.make(env_id).unwrapped.system.sensors)
    policies = list(agents) or ["lqr"]  # an agent is its own factory
    try:
        rows = [r for policy in policies
                for r in evaluate(env_id, policy, estimator, seeds, env_kwargs=kwargs)]
    except ValueError as error:
        return {"cost": None, "failed": 0, "why": str(error).split(";")[0]}
    return {"cost": float(np.mean([r["cost"] for r in rows])),
            "failed": int(sum(r["failed"] for r in rows)), "episodes": len(rows)}


def agent_columns(paths: Sequence[Path]) -> dict[str, dict[str, list[sb3.Agent]]]:
    """``{vehicle: {"ALGO on ESTIMATOR": [agents]}}`` of the agents saved in ``paths``."""
    columns: dict[str, dict[str, list[sb3.Agent]]] = {}
    for path in paths:
        agent = sb3.load_agent(path)
        vehicle = agent.config["env_id"].split("/")[1].removesuffix("-v0")
        name = f"{agent.config['algo']} on {agent.config['estimator'] or 'raw'}"
        columns.setdefault(vehicle, {}).setdefault(name, []).append(agent)
    return columns


def run(vehicles: list[str], sets: list[str],
        agents: dict[str, dict[str, list[sb3.Agent]]] | None = None) -> dict[str, Any]:
    agents = agents or {}
    jobs = [(s, v, n, e) for s in sets for v in vehicles for n in SENSORS
            for e in (*ESTIMATORS, *agents.get(v, {}))]
    results: dict[str, Any] = {}
    for seed_set, vehicle, sensors, column in tqdm(jobs, desc="episodes", unit="cell"):
        trained = agents.get(vehicle, {}).get(column, [])
        estimator = column.split(" on ")[1] if trained else column
        results.setdefault(seed_set, {}).setdefault(vehicle, {}).setdefault(sensors, {})[
            column] = cell(vehicle, estimator, sensors, SEED_SETS[seed_set], trained)
    return results


def _text(c: dict[str, Any]) -> str:
    if c["cost"] is None:
        return "n/a"
    return f"{c['failed']}/{c['episodes']} fail" if c["failed"] else f"{c['cost']:.0f}"


def _columns(results: dict[str, Any]) -> list[str]:
    """The estimators, then every agent column of any vehicle, in order of appearance."""
    names = [c for by_sensors in results.values() for cells in by_sensors.values()
             for c in cells]
    return list(ESTIMATORS) + [c for c in dict.fromkeys(names) if c not in ESTIMATORS]


def table(results: dict[str, Any]) -> str:
    columns = _columns(results)
    lines = ["| vehicle | sensors | " + " | ".join(columns) + " |",
             "|---|---|" + "---|" * len(columns)]
    for vehicle, by_sensors in results.items():
        for sensors, cells in by_sensors.items():
            lines.append(f"| {vehicle} | {sensors} | " + " | ".join(
                _text(cells[c]) if c in cells else "" for c in columns) + " |")
    return "\n".join(lines)


def checks(results: dict[str, Any]) -> list[tuple[str, bool | None, str]]:
    """The acceptance lines (module docstring) on one seed set: (what, verdict, numbers);
    None where it cannot be told (failed episodes)."""
    out = []
    for vehicle, by_sensors in results.items():
        default = by_sensors.get("default")
        if default:
            ref, bound = BOUND.get(vehicle, ("raw", 1.0))
            kf, base = default["kf"], default[ref]
            ok = None if kf["failed"] or base["failed"] else kf["cost"] <= bound * base["cost"]
            out.append((f"{vehicle} default: kf <= {bound:g} x {ref}", ok,
                        f"{_text(kf)} vs {_text(base)}"))
        noisy = by_sensors.get("noise=32")
        if noisy:
            names = [e for e in ("true", "kf", "raw") if noisy[e]["cost"] is not None]
            failed = any(noisy[e]["failed"] for e in names)
            costs = [noisy[e]["cost"] for e in names]
            ok = None if failed else all(a <= b for a, b in zip(costs, costs[1:], strict=False))
            out.append((f"{vehicle} noise=32: " + " <= ".join(names), ok,
                        ", ".join(f"{e} {_text(noisy[e])}" for e in names)))
    return out


def plot(results: dict[str, Any], bench: Run, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    vehicles = list(results)
    fig, axes = plt.subplots(1, len(vehicles), figsize=(3.2 * len(vehicles), 3.2), squeeze=False)
    for ax, vehicle in zip(axes[0], vehicles, strict=True):
        by_sensors = results[vehicle]
        factors = [1.0 if s == "default" else float(s.split("=")[1]) for s in by_sensors]
        for column in _columns({vehicle: by_sensors}):
            costs = [c[column]["cost"] if column in c and c[column]["cost"] is not None and
                     not c[column]["failed"] else np.nan for c in by_sensors.values()]
            style = "o-" if column in ESTIMATORS else "s--"  # LQR solid, agents dashed
            ax.plot(factors, costs, style, label=column if column in ESTIMATORS else
                    f"{column} (agent)")
        ax.set(xscale="log", yscale="log", title=vehicle, xlabel="sensor noise x default")
        ax.set_xticks(factors, [f"{f:g}" for f in factors])
    axes[0][0].set_ylabel("cost (held-out seeds)")
    for ax in axes[0]:
        ax.legend(fontsize=6)
    fig.tight_layout()
    agents = any(c not in ESTIMATORS for cells in results.values() for by in cells.values()
                 for c in by)
    bench.figure(fig, path, "Cost against sensor noise per estimator, LQR solid"
                 + (", agents dashed" if agents else ""), dpi=120)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--vehicles", nargs="+", default=list(VEHICLES), choices=VEHICLES)
    parser.add_argument("--sets", nargs="+", default=list(SEED_SETS), choices=list(SEED_SETS))
    parser.add_argument("--plot", type=Path, default=REPO / "docs" / "filters.png",
                        help="figure path (default docs/filters.png; '' for none)")
    parser.add_argument("--agents", nargs="+", type=Path, default=[], metavar="DIR",
                        help="trained agents' folders: a column per algorithm and estimator")
    parser.add_argument("--json", help="write the results here")
    add_docs_option(parser, "filters")
    args = parser.parse_args(argv)
    missing = [str(d) for d in args.agents if not (d / "config.json").exists()]
    if missing:
        parser.error(f"--agents: no trained agent (config.json) in {', '.join(missing)}")
    check_page_path(parser, args.docs)
    with benchmark_run("filters", argv) as bench:
        if not args.agents:
            bench.note("No trained agents were given (`--agents DIR ...`), so this run has no "
                       "agent columns: the agents behind `kf` and on the raw sensors are trained "
                       "by `benchmarks/rl_vs_lqr.py`, and none were on the machine that ran it.")
        results = run(args.vehicles, args.sets, agent_columns(args.agents))
        for seed_set, by_vehicle in results.items():
            seeds = SEED_SETS[seed_set]
            heading = (f"{seed_set.replace('_', ' ').capitalize()} seeds {seeds.start}-"
                       f"{seeds.stop - 1}")
            print(f"\n{heading}, cost (mean; LQR behind each estimator, agents behind theirs):\n")
            bench.show(table(by_vehicle), heading)
            bench.show("\n".join(f"{verdict_text(ok):<12}{what}: {numbers}"
                                 for what, ok, numbers in checks(by_vehicle)),
                       f"{heading}: acceptance", markdown=False)
        if str(args.plot) not in ("", "."):
            plot(results["held_out" if "held_out" in results else args.sets[0]], bench,
                 args.plot)
    if args.json:
        write_json(args.json, results, indent=1)
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    return 0


def verdict_text(ok: bool | None) -> str:
    """An acceptance line's verdict: pass, FAIL or cannot tell (failed episodes)."""
    return {True: "pass", False: "FAIL", None: "cannot tell"}[ok]


if __name__ == "__main__":
    raise SystemExit(main())
