"""Environment throughput of every vehicle against Gymnasium's CartPole, in one run on one machine.

Absolute steps/s on shared machines are noise; the ratios to CartPole measured in the same run
are the numbers to compare. Each figure is the best of several interleaved repeats, and every
vehicle's figure is taken next to a CartPole figure of the same repeat.

    python benchmarks/throughput.py [--repeats 3] [--steps 2000] [--sizes 1 64 1024]
                                    [--envs USV ROV ...] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from collections.abc import Callable

import gymnasium as gym
import numpy as np

from marine_envs import ENVIRONMENTS

CARTPOLE = "CartPole-v1"
#: acceptance (minimum) and goal ratios to CartPole, by (environment, case)
TARGETS = {("USV", "single"): (0.3, 0.6), ("USV", 1024): (0.25, 0.5), ("ROV", 1024): (0.05, 0.2)}
SHORT = {env_id.split("/")[1].removesuffix("-v0"): env_id for env_id in ENVIRONMENTS}


def _neutral_action(env: gym.Env | gym.vector.VectorEnv) -> np.ndarray | int:
    """An action that keeps episodes going: the nominal input of a marine vehicle (its trim),
    1 for CartPole."""
    sim = getattr(env.unwrapped, "sim", None)
    if sim is None:
        space = env.action_space
        return np.ones(space.shape, dtype=np.int64) if space.shape else 1
    return np.broadcast_to(sim.nominal_action(), env.action_space.shape).astype(np.float32)


def single_stepper(env_id: str) -> Callable[[int], float]:
    """Seconds to run n steps of ``gym.make(env_id)`` (with its standard wrappers)."""
    env = gym.make(env_id)
    env.reset(seed=0)
    action = _neutral_action(env)

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
    action = _neutral_action(env)

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


def measure(vehicles: list[str], sizes: list[int], steps: int, repeats: int) -> list[dict]:
    """Rows ``{vehicle, case, reference, reference_steps_per_s, steps_per_s, ratio}``."""
    from tqdm import tqdm

    cases: list[str | int] = ["single", *sizes]
    rows = []
    for case in tqdm(cases, desc="benchmark", unit="case"):
        if case == "single":
            make, n, reference = single_stepper, 1, CARTPOLE
            # single steps are cheap: more of them for a stable figure
            count = steps * 5
            steppers = {"ref": make(CARTPOLE), **{v: make(SHORT[v]) for v in vehicles}}
        else:
            n, reference, count = case, "CartPoleVectorEnv", max(20, steps * 64 // max(case, 64))
            steppers = {"ref": vector_stepper(CARTPOLE, n),
                        **{v: vector_stepper(SHORT[v], n) for v in vehicles}}
        rate = best_rate(steppers, count, repeats, scale=n)
        for vehicle in vehicles:
            rows.append({"vehicle": vehicle, "case": case, "reference": reference,
                         "reference_steps_per_s": rate["ref"], "steps_per_s": rate[vehicle],
                         "ratio": rate[vehicle] / rate["ref"]})
    return rows


def format_table(rows: list[dict]) -> str:
    """The rows as a table, with the targets of the issues where they set one."""
    lines = [f"{'vehicle':<12}{'case':<10}{'reference':<19}{'ref steps/s':>13}"
             f"{'steps/s':>12}{'ratio':>8}{'target (goal)':>17}"]
    for row in rows:
        case = "single" if row["case"] == "single" else f"N={row['case']}"
        target = TARGETS.get((row["vehicle"], row["case"]))
        mark = "" if target is None else (f"{target[0]:.2f} ({target[1]:.2f}) "
                                          + ("ok" if row["ratio"] >= target[0] else "LOW"))
        lines.append(f"{row['vehicle']:<12}{case:<10}{row['reference']:<19}"
                     f"{row['reference_steps_per_s']:>13,.0f}{row['steps_per_s']:>12,.0f}"
                     f"{row['ratio']:>8.3f}{mark:>17}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats (3)")
    parser.add_argument("--steps", type=int, default=2000,
                        help="steps per repeat for N <= 64; fewer for larger N (2000)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 64, 1024],
                        help="vector sizes N (1 64 1024)")
    parser.add_argument("--envs", nargs="+", default=list(SHORT), choices=list(SHORT),
                        help="vehicles (all)")
    parser.add_argument("--json", help="also write the results as JSON")
    args = parser.parse_args()
    warnings.filterwarnings("ignore")
    rows = measure(args.envs, args.sizes, args.steps, args.repeats)
    print(format_table(rows))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=2)


if __name__ == "__main__":
    main()
