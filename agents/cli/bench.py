"""``marine bench``: the estimator x controller benchmark grid over vehicles, seas and sensors,
locally or on Ray. Its arguments (:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import json
import os
import shutil
import sys
from pathlib import Path

from . import common

#: The command's line in ``marine --help``.
HELP = "estimator x controller benchmark grid over vehicles, seas and sensors"
DESCRIPTION = """\
Run a grid of vehicles x estimators x sea states x sensor degradations x controllers x seeds.
Every controller is scored by the task's quadratic cost on the same seeded episodes; each cell
(all axes but the seed) runs its seeds as one batch. SB3 agents named in --controllers are
trained first, one per vehicle and estimator, on the moderate sea and default sensors, and
kept in DIR/agents. Finished cells are kept in DIR/rows.csv and not run again.

outputs (in --out):
  rows.csv, rows.parquet  a row per seed: vehicle, estimator, controller, sea, sensor, seed,
                          status (ok or n/a: why), cost, failed, seconds, rms_<state> and
                          rms_<input> (SI; _deg: degrees), saturated, estimation_rms_<state>
  summary.md              cost mean ± std per cell; the checks KF <= raw, true <= KF under LQR
  cost_by_estimator.png   cost by estimator per vehicle, a bar per controller
  degradation.png         cost against each degradation's level (if it has several levels)

on a Ray cluster: start it (ray start --head on one machine, ray start --address HEAD:6379 on
the others, each with marine-envs installed), then run on any of them:
  marine bench --backend ray --address auto --seeds 20 --sensors default noise=4 noise=16
(with --controllers ppo, --out must be on a filesystem all machines share: tasks save agents)
"""

#: What ``marine bench`` writes into its --out folder; --force clears exactly these.
BENCH_OWNED = ("rows.csv", "rows.parquet", "summary.md", "cost_by_estimator.png",
               "degradation.png", "grid.json", "agents")

GRID_OPTIONS = ("vehicles", "estimators", "controllers", "seas", "sensors", "seeds", "seconds",
                "timesteps")


#: The description is laid out by hand.
FORMATTER = argparse.RawDescriptionHelpFormatter
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "json": 'also write {"rows": [...]} as JSON',
    "force": "start afresh: clear what an earlier run wrote into --out, and "
             "replace --json and --report",
    "quiet": "no progress bars",
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine bench``'s own arguments."""
    from estimators import registry

    axes = parser.add_argument_group("the grid (each a space-separated list)")
    axes.add_argument("--vehicles", nargs="+", type=str,
                      help="usv hydrofoil rov dp hovercraft (default: all)")
    axes.add_argument("--estimators", nargs="+",
                      help=f"{' '.join(registry.names())}, or one registered with "
                           "estimators.registry.register (default: true raw kf akf ekf)")
    axes.add_argument("--controllers", nargs="+",
                      help="lqr, nominal, ppo/sac/td3/a2c (trained here per vehicle and "
                           "estimator) or sb3:DIR (a 'marine train' output) (default: lqr)")
    axes.add_argument("--seas", nargs="+", help="calm moderate rough (default: moderate)")
    axes.add_argument("--sensors", nargs="+",
                      help="default, or degradations kind=level joined by +: noise=K (K x the "
                           "default noise), quant=K (a step of K default stds), dropout=P, "
                           "delay=N (control periods); e.g. default noise=4 dropout=0.2")
    axes.add_argument("--seeds", type=common.positive_int,
                      help="episodes per cell, seeds 0..N-1 (default 5)")
    axes.add_argument("--seconds", type=common.positive_float,
                      help="episode length, s (default: the env's)")
    axes.add_argument("--timesteps", type=common.positive_int,
                      help="training steps of each agent the grid trains (default 100000)")
    parser.add_argument("--quick", action="store_true",
                        help="a small grid over all five vehicles: true raw kf akf, lqr and ppo, "
                             "default and noise=32 sensors, 3 seeds of 60 s, 20000-step PPO "
                             "(other options override its settings)")
    parser.add_argument("--out", default="bench", metavar="DIR",
                        help="rows.csv, summary.md, figures, trained agents; a rerun of the "
                             "same grid resumes (default: bench)")
    parser.add_argument("--backend", choices=("local", "ray"), default="local",
                        help="local processes (default) or Ray tasks")
    parser.add_argument("--address", help="Ray cluster address (auto, or HOST:PORT); without it "
                                          "--backend ray starts a local Ray")
    parser.add_argument("--workers", type=common.positive_int, default=os.cpu_count() or 1,
                        help="processes (local) or CPUs of the local Ray (default: all cores)")
    parser.add_argument("--report", metavar="DIR",
                        help="also write DIR/index.html: the tables and figures in one page")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine bench`` as ``args`` ask; the exit code."""
    from ..benchmark import Grid, markdown_summary, run_grid, write_outputs, write_report
    from ..benchmark.grid import cell_key
    from ..benchmark.run import load_rows

    chosen = {k: tuple(v) if isinstance(v, list) else v for k, v in vars(args).items()
              if k in GRID_OPTIONS and v is not None}
    grid = dataclasses.replace(Grid.quick(), **chosen) if args.quick else Grid(**chosen)
    for name in grid.estimators:
        common.check_estimator(name, "--estimators")
    if args.backend == "ray" and importlib.util.find_spec("ray") is None:
        raise ImportError("--backend ray needs Ray: pip install \"marine-envs[ray]\"")
    for controller in grid.controllers:
        if controller.startswith("sb3:"):
            from ..sb3 import find_agent

            find_agent(Path(controller[4:]))
    out = Path(args.out)
    resuming = (out / "grid.json").is_file() and not args.force  # a rerun resumes (documented)
    if not resuming:
        common.output_dir(args.out, args.force, "--out", _bench_owned, " (without its grid.json)")
    # resuming, the grid's own summaries inside --out (e.g. --report bench/report) are redone
    def own(path: str | None) -> bool:
        return resuming and path is not None and out.resolve() in Path(path).resolve().parents

    json_out = common.output_file(args.json, args.force or own(args.json), "--json", creates=out)
    report = None if args.report is None else common.output_dir(
        args.report, args.force or own(args.report), "--report",
        lambda d: ["index.html"] if (d / "index.html").exists() else [])
    common.distinct(("--json", json_out), *(("--out", out / name) for name in BENCH_OWNED),
                    ("--report", None if report is None else report / "index.html"))
    if resuming:
        before = json.loads((out / "grid.json").read_text())
        if before != json.loads(json.dumps(grid.settings())):
            raise ValueError(f"--out {out} holds a grid run with {before}, not "
                             f"{grid.settings()}: resume it with the same --seeds/--seconds/"
                             "--timesteps, use another --out, or --force to start afresh")
        done = {cell_key(r) for r in load_rows(out).to_dict("records")}
        cells = grid.cells()
        print(f"marine bench: resuming {out}: {sum(cell_key(c) in done for c in cells)} of "
              f"{len(cells)} cells done (--force starts afresh)", file=sys.stderr)
    elif args.force:
        for name in _bench_owned(out):
            if (out / name).is_dir():
                shutil.rmtree(out / name)
            else:
                (out / name).unlink()
    rows = run_grid(grid, out, args.backend, args.workers, args.address, not args.quiet)
    written = write_outputs(rows, out)
    print(markdown_summary(rows))
    if report is not None:
        written.append(write_report(rows, out, report, grid))
    if json_out is not None:
        from marine_envs.files import write_json

        records = json.loads(rows.to_json(orient="records"))
        json_out.parent.mkdir(parents=True, exist_ok=True)  # inside --out: made with it
        write_json(json_out, {"rows": records}, indent=1)
        written.append(json_out)
    print("wrote " + ", ".join(map(str, written)))
    return 0


def _bench_owned(out: Path) -> list[str]:
    return [name for name in BENCH_OWNED if (out / name).exists()]
