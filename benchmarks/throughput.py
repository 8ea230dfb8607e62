"""Environment throughput against Gymnasium's CartPole, measured in one run on one machine.

Absolute steps/s on shared machines are noise; the ratios to CartPole measured in the same run
are the numbers to compare. Each figure is the best of several interleaved repeats.

    python benchmarks/throughput.py [--repeats 5] [--steps 3000] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import marine_envs  # noqa: F401

USV = "marine_envs/USV-v0"
# acceptance (minimum) and goal ratios of the foundation issue
TARGETS = {"single": (0.3, 0.6), 1024: (0.25, 0.5)}


def single_stepper(env_id: str) -> Callable[[int], float]:
    """Seconds to run n steps of ``gym.make(env_id)`` (with its standard wrappers)."""
    env = gym.make(env_id)
    env.reset(seed=0)
    action = np.zeros(env.action_space.shape, dtype=np.float32) if env_id == USV else 1

    def run(n: int) -> float:
        start = time.perf_counter()
        for _ in range(n):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run


def vector_stepper(env_id: str, num_envs: int) -> Callable[[int], float]:
    """Seconds to run n steps of the native vector env (auto-resets included)."""
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    action = (np.zeros((num_envs, 1), dtype=np.float32) if env_id == USV
              else np.ones(num_envs, dtype=np.int64))

    def run(n: int) -> float:
        start = time.perf_counter()
        for _ in range(n):
            env.step(action)
        return time.perf_counter() - start

    return run


def best_rate(steppers: dict[str, Callable[[int], float]], steps: int, repeats: int,
              scale: int = 1) -> dict[str, float]:
    """Best env-steps/s of each stepper over ``repeats`` interleaved runs."""
    best = dict.fromkeys(steppers, 0.0)
    for _ in range(repeats):
        for name, run in steppers.items():
            best[name] = max(best[name], steps * scale / run(steps))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5, help="interleaved repeats (5)")
    parser.add_argument("--steps", type=int, default=3000, help="steps per repeat (3000)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 64, 1024],
                        help="vector sizes N (1 64 1024)")
    parser.add_argument("--json", help="also write the results as JSON")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")

    rows = []
    single = best_rate({"cartpole": single_stepper("CartPole-v1"), "usv": single_stepper(USV)},
                       args.steps * 5, args.repeats)
    rows.append(("single env (gym.make)", "CartPole-v1", single["cartpole"], single["usv"],
                 TARGETS["single"]))
    for n in args.sizes:
        rate = best_rate({"cartpole": vector_stepper("CartPole-v1", n),
                          "usv": vector_stepper(USV, n)}, args.steps, args.repeats, scale=n)
        rows.append((f"vector env N={n}", "CartPoleVectorEnv", rate["cartpole"], rate["usv"],
                     TARGETS.get(n)))

    print(f"{'case':<24}{'reference':<20}{'ref steps/s':>14}{'USV steps/s':>14}{'ratio':>8}"
          f"{'target (goal)':>16}")
    results = []
    for case, reference, ref_rate, usv_rate, target in rows:
        ratio = usv_rate / ref_rate
        mark = "" if target is None else (f"{target[0]:.2f} ({target[1]:.2f}) "
                                          + ("ok" if ratio >= target[0] else "LOW"))
        print(f"{case:<24}{reference:<20}{ref_rate:>14,.0f}{usv_rate:>14,.0f}{ratio:>8.2f}"
              f"{mark:>16}")
        results.append({"case": case, "reference": reference, "reference_steps_per_s": ref_rate,
                        "usv_steps_per_s": usv_rate, "ratio": ratio})
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)


if __name__ == "__main__":
    main()
