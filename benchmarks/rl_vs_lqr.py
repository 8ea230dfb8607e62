"""RL against LQR on the same state estimate, in one run.

For each environment, trains an SB3 agent with the YAML's settings (``agents/hyperparams.yaml``)
behind the estimator, then scores it and the task's LQR behind the same estimator, on the same
seeds and full registered episodes (``agents.evaluation.evaluate``). The table gives the training
steps and wall time, each controller's cost (mean +- std over the episodes) and failed episodes,
and the ratio of mean costs RL / LQR. An agent fails the comparison if any of its episodes fails:
a crash ends the cost early, so its cost alone would flatter it.

    python benchmarks/rl_vs_lqr.py [--envs USV Hydrofoil] [--algo ppo] [--estimator kf]
                                   [--lqr-estimator kf] [--episodes 10] [--timesteps N] [--seed 0]
                                   [--out runs/rl_vs_lqr]
                                   [--evaluate-only] [--json out.json] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from _common import add_docs_option, benchmark_run, check_page_path  # noqa: E402

from agents import evaluation, sb3  # noqa: E402
from marine_envs import ENVIRONMENTS  # noqa: E402
from marine_envs.files import write_json  # noqa: E402

SHORT = {env_id.split("/")[1].removesuffix("-v0"): env_id for env_id in ENVIRONMENTS}
FIRST_SEED = 1000  # of the evaluation episodes; training boats start from seeds seed, ...
TOLERANCE = 1.25  # the "within 25 % of LQR"
TITLE = "RL against LQR on the same estimate"
ABOUT = """\
An SB3 agent trained with the YAML's settings (`agents/hyperparams.yaml`) behind an estimator,
then scored with the task's LQR behind the same estimator (or the one given) on the same
evaluation seeds (1000 onwards) and full registered episodes (`agents.evaluation.evaluate`).
The table gives the training steps and wall time, each controller's cost (mean ± std over the
episodes) and failed episodes, and the ratio of mean costs RL / LQR. An agent with a failed
episode does not pass, whatever its cost: a crash ends the cost early."""


def _cost(rows: list[dict[str, Any]]) -> tuple[float, float, int]:
    costs = np.array([r["cost"] for r in rows])
    spread = float(costs.std(ddof=1)) if costs.size > 1 else 0.0
    return float(costs.mean()), spread, int(sum(r["failed"] for r in rows))


def compare(env_id: str, algo: str, estimator: str, episodes: int, out: Path,
            timesteps: int | None = None, seed: int = 0, train: bool = True,
            lqr_estimator: str | None = None) -> dict[str, Any]:
    """Train (unless ``train`` is False: reuse the agent in ``out``), then score the agent
    behind ``estimator`` and LQR behind ``lqr_estimator`` (default: the same) on seeds
    ``FIRST_SEED, ...``; one row of the table."""
    lqr_estimator = lqr_estimator or estimator
    if train:
        sb3.train(env_id, algo, estimator, timesteps, out, seed=seed, progress_bar=True)
    agent = sb3.load_agent(out)
    seeds = range(FIRST_SEED, FIRST_SEED + episodes)
    rl = _cost(evaluation.evaluate(env_id, agent, estimator, seeds))
    lqr = _cost(evaluation.evaluate(env_id, "lqr", lqr_estimator, seeds))
    ratio = rl[0] / lqr[0]
    return {"env": env_id.split("/")[1], "agent": algo, "estimator": estimator,
            "lqr_estimator": lqr_estimator,
            "seed": agent.config["seed"],
            "timesteps": agent.config["timesteps"],
            "wall_seconds": agent.config["wall_seconds"], "episodes": episodes,
            "rl_cost": rl[0], "rl_std": rl[1], "rl_failed": rl[2],
            "lqr_cost": lqr[0], "lqr_std": lqr[1], "lqr_failed": lqr[2], "ratio": ratio,
            "within_25_percent": rl[2] == 0 and ratio <= TOLERANCE}


def format_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a Markdown table."""
    lines = ["| env | agent | estimator | seed | training steps | wall time | episodes | RL cost "
             "| RL failed | LQR behind | LQR cost | LQR failed | RL / LQR | within 25 % |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---|"]
    for r in rows:
        lines.append(
            f"| {r['env']} | {r['agent']} | {r['estimator']} | {r['seed']} | {r['timesteps']} | "
            f"{r['wall_seconds']:.0f} s | {r['episodes']} | "
            f"{r['rl_cost']:.0f} ± {r['rl_std']:.0f} | {r['rl_failed']} | "
            f"{r['lqr_estimator']} | {r['lqr_cost']:.0f} ± {r['lqr_std']:.0f} | "
            f"{r['lqr_failed']} | "
            f"{r['ratio']:.2f} | {'yes' if r['within_25_percent'] else 'no'} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["USV", "Hydrofoil"], choices=sorted(SHORT))
    parser.add_argument("--algo", default="ppo", choices=sorted(sb3.ALGOS))
    parser.add_argument("--estimator", default="kf",
                        help="what both controllers see: true, raw or a registered estimator")
    parser.add_argument("--lqr-estimator", default=None,
                        help="what LQR sees, if not the agent's (e.g. an agent on the raw "
                             "sensors against LQR behind kf)")
    parser.add_argument("--episodes", type=int, default=10, help="evaluation episodes per env")
    parser.add_argument("--timesteps", type=int, default=None,
                        help="training steps (default: the YAML's n_timesteps per env)")
    parser.add_argument("--seed", type=int, default=0, help="training seed (default 0)")
    parser.add_argument("--out", type=Path, default=Path("runs/rl_vs_lqr"),
                        help="agents are saved in OUT/ENV-ALGO-ESTIMATOR-seedSEED")
    parser.add_argument("--evaluate-only", action="store_true",
                        help="score the agents already in --out instead of training them")
    parser.add_argument("--json", metavar="PATH", help="also write the rows as JSON")
    add_docs_option(parser, "rl_vs_lqr")
    args = parser.parse_args(argv)
    named = [name for name in sb3.estimator_choices() if name is not None]
    for option, name in (("--estimator", args.estimator), ("--lqr-estimator", args.lqr_estimator)):
        if name is not None and name not in named:
            parser.error(f"{option} {name!r}: one of {named}")
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    dirs = {name: args.out / f"{name}-{args.algo}-{args.estimator}-seed{args.seed}"
            for name in args.envs}
    missing = [str(d) for d in dirs.values() if not (d / "config.json").exists()]
    if args.evaluate_only and missing:
        parser.error(f"--evaluate-only: no trained agent in {', '.join(missing)}")
    check_page_path(parser, args.docs)
    with benchmark_run("rl_vs_lqr", argv) as bench:
        rows = [compare(SHORT[name], args.algo, args.estimator, args.episodes, path,
                        args.timesteps, args.seed, train=not args.evaluate_only,
                        lqr_estimator=args.lqr_estimator)
                for name, path in dirs.items()]
        bench.show(format_table(rows), f"{args.algo} behind {args.estimator}, training seed "
                   f"{args.seed}")
    if args.json:
        write_json(args.json, {"rows": rows})
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)


if __name__ == "__main__":
    main()
