"""SB3 training throughput on our batched environment against SB3's own DummyVecEnv, in one run.

Both backends train the same PPO (the YAML's settings, ``n_envs`` boats) for the same number of
environment steps; the rows give environment steps per second, learning included, and the
ratio native / dummy measured side by side. A second pair of rows times the vector env alone
(random actions through SB3's ``VecEnv`` interface), where the batching shows undiluted.
Absolute numbers on shared machines are noise; the ratios are the result.

    python benchmarks/sb3_throughput.py [--envs USV ROV] [--timesteps 16384] [--n-envs 8]
                                        [--estimator kf] [--repeats 2] [--json out.json]
                                        [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402
from _common import add_docs_option, benchmark_run, check_page_path  # noqa: E402

from agents.sb3 import make_vec_env, train  # noqa: E402
from marine_envs import ENVIRONMENTS  # noqa: E402
from marine_envs.files import write_json  # noqa: E402

TITLE = "SB3 throughput"
ABOUT = """\
Stable-Baselines3 on the native batched environment (through `agents.sb3.SB3VecEnv`) against
SB3's own `DummyVecEnv` of the same environment, both measured in this run: PPO training with
the YAML's settings for the same number of environment steps (learning included), and the
vector environment alone under random actions through SB3's `VecEnv` interface, where the
batching shows undiluted. Each figure is the best of interleaved repeats (both backends see the
same machine load), in environment steps per second; the ratio native / DummyVecEnv is the
result, absolute rates on a shared machine are not. Torch runs on one thread."""

SHORT = {env_id.split("/")[1].removesuffix("-v0"): env_id for env_id in ENVIRONMENTS}
BACKENDS = ("native", "dummy")


def training_rate(env_id: str, backend: str, timesteps: int, n_envs: int,
                  estimator: str | None) -> float:
    """Environment steps per second of a PPO training run, learning included."""
    with tempfile.TemporaryDirectory() as out:
        result = train(env_id, "ppo", estimator, timesteps, Path(out), n_envs=n_envs,
                       backend=backend, progress_bar=False)
    return result.steps_per_second


def stepping_rate(env_id: str, backend: str, steps: int, n_envs: int,
                  estimator: str | None) -> float:
    """Environment steps per second of the SB3 VecEnv alone, under random actions."""
    venv = make_vec_env(env_id, n_envs, estimator, seed=0, backend=backend)
    venv.reset()
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (steps // n_envs, n_envs, *venv.action_space.shape))
    start = time.perf_counter()
    for action in actions.astype(np.float32):
        venv.step(action)
    elapsed = time.perf_counter() - start
    venv.close()
    return actions.shape[0] * n_envs / elapsed


def measure(envs: Sequence[str], timesteps: int, n_envs: int, estimator: str | None,
            repeats: int) -> list[dict]:
    """Per env, PPO training and env stepping on both backends: the best of ``repeats``
    interleaved runs and the ratio native / dummy."""
    rows = []
    for name in envs:
        for what, rate_of, size in (("PPO training", training_rate, timesteps),
                                    ("env stepping", stepping_rate, 8 * timesteps)):
            best = dict.fromkeys(BACKENDS, 0.0)
            for _ in range(repeats):  # interleaved, so both see the same machine load
                for backend in BACKENDS:
                    rate = rate_of(SHORT[name], backend, size, n_envs, estimator)
                    best[backend] = max(best[backend], rate)
            rows.append({"env": name, "what": what, "n_envs": n_envs,
                         "estimator": estimator or "raw", "native_steps_s": best["native"],
                         "dummy_steps_s": best["dummy"],
                         "ratio": best["native"] / best["dummy"]})
    return rows


def format_table(rows: Sequence[dict]) -> str:
    """The rows as a Markdown table."""
    lines = ["| env | what | n_envs | estimator | native steps/s | DummyVecEnv steps/s | ratio |",
             "|---|---|---:|---|---:|---:|---:|"]
    lines += [f"| {r['env']} | {r['what']} | {r['n_envs']} | {r['estimator']} | "
              f"{r['native_steps_s']:.0f} | {r['dummy_steps_s']:.0f} | {r['ratio']:.2f} |"
              for r in rows]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["USV", "ROV"], choices=sorted(SHORT))
    parser.add_argument("--timesteps", type=int, default=16384, help="PPO steps per run")
    parser.add_argument("--n-envs", type=int, default=8, help="boats per vector env")
    parser.add_argument("--estimator", default=None, help="e.g. kf (default: raw sensors)")
    parser.add_argument("--repeats", type=int, default=2, help="best of this many runs")
    parser.add_argument("--json", metavar="PATH", help="also write the rows as JSON")
    add_docs_option(parser, "sb3_throughput")
    args = parser.parse_args(argv)
    check_page_path(parser, args.docs)
    torch.set_num_threads(1)
    with benchmark_run("sb3_throughput", argv) as bench:
        rows = measure(args.envs, args.timesteps, args.n_envs, args.estimator, args.repeats)
        bench.show(format_table(rows), f"Native against DummyVecEnv, best of {args.repeats}")
    if args.json:
        write_json(args.json, {"rows": rows})
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)


if __name__ == "__main__":
    main()
