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
                                 [--json out.json]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import marine_envs  # noqa: F401
from agents import sb3
from agents.benchmark.grid import sensor_kwargs
from agents.evaluation import evaluate

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
    kwargs = sensor_kwargs(sensors, gym.make(env_id).unwrapped.sim.sensors)
    policies = [(lambda venv, a=agent: a) for agent in agents] or ["lqr"]
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


def plot(results: dict[str, Any], path: str) -> None:
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
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter,
                                     epilog=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--vehicles", nargs="+", default=list(VEHICLES), choices=VEHICLES)
    parser.add_argument("--sets", nargs="+", default=list(SEED_SETS), choices=list(SEED_SETS))
    parser.add_argument("--plot", default="docs/filters.png", help="figure path ('' for none)")
    parser.add_argument("--agents", nargs="+", type=Path, default=[], metavar="DIR",
                        help="trained agents' folders: a column per algorithm and estimator")
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args(argv)
    missing = [str(d) for d in args.agents if not (d / "config.json").exists()]
    if missing:
        parser.error(f"--agents: no trained agent (config.json) in {', '.join(missing)}")
    results = run(args.vehicles, args.sets, agent_columns(args.agents))
    for seed_set, by_vehicle in results.items():
        seeds = SEED_SETS[seed_set]
        print(f"\n{seed_set} seeds {seeds.start}-{seeds.stop - 1}, cost (mean; LQR behind "
              "each estimator, agents behind theirs):\n")
        print(table(by_vehicle))
        print()
        for what, ok, numbers in checks(by_vehicle):
            verdict = {True: "pass", False: "FAIL", None: "cannot tell"}[ok]
            print(f"{verdict:<12}{what}: {numbers}")
    if args.plot:
        plot(results["held_out" if "held_out" in results else args.sets[0]], args.plot)
        print(f"\nfigure: {args.plot}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
