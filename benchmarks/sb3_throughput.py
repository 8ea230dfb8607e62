"""SB3 training throughput on our batched environment against SB3's own DummyVecEnv, in one run.

Both backends train the same PPO (the YAML's settings, ``n_envs`` boats) for the same number of
environment steps; the rows give environment steps per second, learning included, and the
ratio native / dummy measured side by side. A second pair of rows times the vector env alone
(random actions through SB3's ``VecEnv`` interface), where the batching shows undiluted.
Absolute numbers on shared machines are noise; the ratios are the result.

    python benchmarks/sb3_throughput.py [--envs USV ROV] [--timesteps 16384] [--n-envs 8]
                                        [--estimator kf] [--repeats 2] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from agents.sb3 import make_vec_env, train
from marine_envs import ENVIRONMENTS

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", nargs="+", default=["USV", "ROV"], choices=sorted(SHORT))
    parser.add_argument("--timesteps", type=int, default=16384, help="PPO steps per run")
    parser.add_argument("--n-envs", type=int, default=8, help="boats per vector env")
    parser.add_argument("--estimator", default=None, help="e.g. kf (default: raw sensors)")
    parser.add_argument("--repeats", type=int, default=2, help="best of this many runs")
    parser.add_argument("--json", metavar="PATH", help="also write the rows as JSON")
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    for name in args.envs:
        env_id = SHORT[name]
        for what, measure, size in (("PPO training", training_rate, args.timesteps),
                                    ("env stepping", stepping_rate, 8 * args.timesteps)):
            best = dict.fromkeys(BACKENDS, 0.0)
            for _ in range(args.repeats):  # interleaved, so both see the same machine load
                for backend in BACKENDS:
                    rate = measure(env_id, backend, size, args.n_envs, args.estimator)
                    best[backend] = max(best[backend], rate)
            rows.append({"env": name, "what": what, "n_envs": args.n_envs,
                         "estimator": args.estimator or "raw", "native_steps_s": best["native"],
                         "dummy_steps_s": best["dummy"],
                         "ratio": best["native"] / best["dummy"]})
    print("| env | what | n_envs | estimator | native steps/s | DummyVecEnv steps/s | ratio |")
    print("|---|---|---:|---|---:|---:|---:|")
    for r in rows:
        print(f"| {r['env']} | {r['what']} | {r['n_envs']} | {r['estimator']} | "
              f"{r['native_steps_s']:.0f} | {r['dummy_steps_s']:.0f} | {r['ratio']:.2f} |")
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows}, indent=2) + "\n")


if __name__ == "__main__":
    main()
