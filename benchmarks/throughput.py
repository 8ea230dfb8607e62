"""Environment throughput of every vehicle against Gymnasium's CartPole, in one run on one machine,
and the time each vehicle's compiled kernels take to build.

Absolute steps/s on shared machines are noise; the ratios to CartPole measured in the same run
are the numbers to compare. Every repeat times each vehicle next to a CartPole figure of the same
repeat (interleaved), over at least two 256-step blocks of the per-boat random streams (waves,
sensor noise, current, wind: their refills are part of the cost, and at N = 1024 a large part),
and the table gives the ratio's minimum, median and maximum over the repeats, against issue 23's
acceptance: a single env through ``gym.make`` >= 0.8x CartPole-v1
(ROV >= 0.5x), the native vector env at N = 1024 >= 0.25x CartPoleVectorEnv (USV >= 0.75x, ROV
>= 0.15x). Each vehicle is held at its trim (episodes that end are reset, as in training).

Regimes (issue 59), each paired with its reference in the same interleaved repeats: the
hydrofoil under zero action, which broaches every ~25 steps (the early-RL regime: a reset every
few steps, as Gymnasium's autoreset and SB3's same-step restart do them), against CartPole-v1
(target >= 0.5x) and CartPoleVectorEnv at N = 1024 (>= 0.1x); the USV at N = 1024 with BLAS on
its default threads against one thread (the environment runs its products on one thread itself:
>= 0.9x); and a diagnosed USV (a state effect and an actuator effect) against the nominal USV
(within 1.5x of its time: >= 0.67x).

Compile time: the first ``gym.make`` + reset + step of each vehicle in a fresh process with an
empty numba cache (what a new machine pays once; target < 5 s), and again with the cache that
run left (what every later process pays).

    python benchmarks/throughput.py [--repeats 3] [--steps 2000] [--sizes 1 64 1024]
                                    [--envs USV ROV ...] [--no-compile] [--no-regimes]
                                    [--regime-size 1024] [--json out.json] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import contextlib  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from _common import add_docs_option, benchmark_run, check_page_path  # noqa: E402

from marine_envs import ENVIRONMENTS  # noqa: E402
from marine_envs.blocks import BLOCK  # noqa: E402
from marine_envs.files import write_json  # noqa: E402
from marine_envs.models.effects import Effect  # noqa: E402

TITLE = "Environment throughput"
ABOUT = """\
Steps per second of every vehicle's single environment (through `gym.make`, with its standard
wrappers) against Gymnasium's `CartPole-v1`, and of its native vector environment at each size
N against Gymnasium's `CartPoleVectorEnv` of the same N, each vehicle held at its trim. Every
repeat times each vehicle next to a CartPole figure of the same repeat (interleaved), over at
least two 256-step blocks of the per-boat random streams (their refills are part of the cost),
and the ratio column gives the minimum, median and maximum over the repeats: absolute rates on
a shared machine are noise, the ratios to CartPole measured in the same run are the result. The
target column is issue 23's acceptance. The second table is the time of the first `gym.make` +
reset + step of each vehicle in a fresh process with an empty numba cache (what a new machine
pays once) and again with the cache that run left; these are seconds, not ratios, and grow
with the machine's load. The regimes table pairs what issue 59 compares: the hydrofoil under
zero action (it broaches every ~25 steps, so resets dominate) against CartPole, the USV's vector
env with BLAS on its default threads against one thread, and a diagnosed USV (`effects=`)
against the nominal one; its ratio column is the case's steps/s over the reference's."""

CARTPOLE = "CartPole-v1"
SHORT = {env_id.split("/")[1].removesuffix("-v0"): env_id for env_id in ENVIRONMENTS}
#: issue 23's acceptance ratios to CartPole, by (vehicle, case); other vehicles as "*"
TARGETS = {("*", "single"): 0.8, ("ROV", "single"): 0.5,
           ("*", 1024): 0.25, ("USV", 1024): 0.75, ("ROV", 1024): 0.15}
#: first use of the compiled kernels, s
COMPILE_TARGET = 5.0
#: The diagnosed vessel of issue 59's acceptance: a state effect and an actuator effect.
DIAGNOSED_EFFECTS = (Effect("quadratic_damping", "p", {"c": -1.0}),
                     Effect("input_rate_limit", "delta", {"rate": 0.2}))
#: issue 59's acceptance ratios of the regimes table, by case name
REGIME_TARGETS = {"Hydrofoil, zero action": 0.5, "Hydrofoil, zero action, N": 0.1,
                  "Hydrofoil, zero action, same-step restarts, N": 0.1,
                  "USV, BLAS default threads, N": 0.9, "USV diagnosed": 1 / 1.5,
                  "USV diagnosed, N": 1 / 1.5}


def target(vehicle: str, case: str | int) -> float | None:
    """The acceptance ratio of a (vehicle, case), or None where the issue sets none."""
    return TARGETS.get((vehicle, case), TARGETS.get(("*", case)))


def _neutral_action(env: gym.Env | gym.vector.VectorEnv) -> np.ndarray | int:
    """An action that keeps episodes going: the nominal input of a marine vehicle (its trim),
    1 for CartPole."""
    system = getattr(env.unwrapped, "system", None)
    if system is None:
        space = env.action_space
        return np.ones(space.shape, dtype=np.int64) if space.shape else 1
    nominal = system.actuation.nominal_action(system.model)
    return np.broadcast_to(nominal, env.action_space.shape).astype(np.float32)


def _zero_action(env: gym.Env | gym.vector.VectorEnv) -> np.ndarray:
    """Zero normalised actions (the mid-range input: the hydrofoil broaches within ~25 steps)."""
    return np.zeros(env.action_space.shape, dtype=np.float32)


Action = Callable[[gym.Env | gym.vector.VectorEnv], np.ndarray | int]


def _blas_threads(threads: int | None) -> contextlib.AbstractContextManager:
    """BLAS limited to ``threads`` while a stepper runs (None: as the run set it)."""
    if threads is None:
        return contextlib.nullcontext()
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=threads, user_api="blas")


def single_stepper(env_id: str, action: Action = _neutral_action,
                   **kwargs: object) -> Callable[[int], float]:
    """Seconds to run n steps of ``gym.make(env_id, **kwargs)`` (with its standard wrappers),
    reset when an episode ends (as Gymnasium's and SB3's loops do)."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    chosen = action(env)

    def run(n: int) -> float:
        start = time.perf_counter()
        for _ in range(n):
            _, _, terminated, truncated, _ = env.step(chosen)
            if terminated or truncated:
                env.reset()
        return time.perf_counter() - start

    return run


def vector_stepper(env_id: str, num_envs: int, action: Action = _neutral_action, *,
                   same_step: bool = False, blas_threads: int | None = None,
                   **kwargs: object) -> Callable[[int], float]:
    """Seconds to run n steps of the native vector env: its own autoreset (Gymnasium's
    NEXT_STEP), or with ``same_step`` the finished boats restarted right after the step that
    ended them (``restart(idx)``, as SB3's adapter does); BLAS on ``blas_threads``."""
    env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                       **kwargs)
    env.reset(seed=0)
    chosen = action(env)

    def run(n: int) -> float:
        with _blas_threads(blas_threads):
            start = time.perf_counter()
            for _ in range(n):
                _, _, terminated, truncated, _ = env.step(chosen)
                if same_step:
                    done = np.flatnonzero(terminated | truncated)
                    if done.size:
                        env.unwrapped.restart(done)
            return time.perf_counter() - start

    return run


def rates(steppers: dict[str, Callable[[int], float]], steps: int, repeats: int,
          scale: int = 1) -> dict[str, list[float]]:
    """Env-steps/s of each stepper in each of ``repeats`` interleaved runs (after a warm-up)."""
    for run in steppers.values():
        run(max(1, steps // 10))
    out: dict[str, list[float]] = {name: [] for name in steppers}
    for _ in range(repeats):
        for name, run in steppers.items():
            out[name].append(steps * scale / run(steps))
    return out


def measure(vehicles: list[str], sizes: list[int], steps: int, repeats: int) -> list[dict]:
    """Rows ``{vehicle, case, reference, reference_steps_per_s, steps_per_s, ratios}`` (the
    medians, and the ratio of each repeat)."""
    from tqdm import tqdm

    cases: list[str | int] = ["single", *sizes]
    rows = []
    for case in tqdm(cases, desc="throughput", unit="case"):
        if case == "single":
            n, reference, count = 1, CARTPOLE, steps * 5  # cheap steps: more of them
            steppers = {"ref": single_stepper(CARTPOLE),
                        **{v: single_stepper(SHORT[v]) for v in vehicles}}
        else:
            # at least two blocks of the random streams: their refills are part of the cost
            n, reference = case, "CartPoleVectorEnv"
            count = max(2 * BLOCK, steps * 64 // max(case, 64))
            steppers = {"ref": vector_stepper(CARTPOLE, n),
                        **{v: vector_stepper(SHORT[v], n) for v in vehicles}}
        rate = rates(steppers, count, repeats, scale=n)
        for vehicle in vehicles:
            ratios = [r / ref for r, ref in zip(rate[vehicle], rate["ref"], strict=True)]
            rows.append({"vehicle": vehicle, "case": case, "reference": reference,
                         "reference_steps_per_s": statistics.median(rate["ref"]),
                         "steps_per_s": statistics.median(rate[vehicle]), "ratios": ratios})
    return rows


def blas_threads_now() -> int:
    """The threads numpy's BLAS runs now (called before a benchmark run pins it to one: the
    default, which the regimes table compares one thread against)."""
    import numpy  # noqa: F401  (its BLAS loaded before threadpoolctl looks)
    from threadpoolctl import threadpool_info

    return max([p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"] or [1])


def regimes(size: int, steps: int, repeats: int, blas_default: int) -> list[dict]:
    """Issue 59's paired cases: rows ``{vehicle, case, reference, reference_steps_per_s,
    steps_per_s, ratios, target}``, each timed in the same interleaved repeats as its
    reference (single envs, then vector envs of ``size`` boats; the USV's BLAS on one thread
    and on ``blas_default`` threads)."""
    hydrofoil, usv = SHORT["Hydrofoil"], SHORT["USV"]
    diagnosed = {"effects": list(DIAGNOSED_EFFECTS)}
    single = {"CartPole-v1": single_stepper(CARTPOLE),
              "Hydrofoil, zero action": single_stepper(hydrofoil, _zero_action),
              "USV": single_stepper(usv), "USV diagnosed": single_stepper(usv, **diagnosed)}
    vector = {"CartPoleVectorEnv": vector_stepper(CARTPOLE, size),
              "Hydrofoil, zero action, N": vector_stepper(hydrofoil, size, _zero_action),
              "Hydrofoil, zero action, same-step restarts, N": vector_stepper(
                  hydrofoil, size, _zero_action, same_step=True),
              "USV, N": vector_stepper(usv, size, blas_threads=1),
              "USV, BLAS default threads, N": vector_stepper(usv, size,
                                                             blas_threads=blas_default),
              "USV diagnosed, N": vector_stepper(usv, size, **diagnosed)}
    pairs = [("Hydrofoil, zero action", "CartPole-v1"), ("USV diagnosed", "USV"),
             ("Hydrofoil, zero action, N", "CartPoleVectorEnv"),
             ("Hydrofoil, zero action, same-step restarts, N", "CartPoleVectorEnv"),
             ("USV, N", "CartPoleVectorEnv"), ("USV, BLAS default threads, N", "USV, N"),
             ("USV diagnosed, N", "USV, N")]
    rate = {**rates(single, steps * 5, repeats),
            **rates(vector, max(2 * BLOCK, steps * 64 // max(size, 64)), repeats, scale=size)}
    rows = []
    for case, reference in pairs:
        ratios = [r / ref for r, ref in zip(rate[case], rate[reference], strict=True)]
        label = case.replace(", N", f", N={size}") if case.endswith(", N") else case
        rows.append({"vehicle": case.split(",")[0].split()[0], "case": label,
                     "reference": reference.replace(", N", f", N={size}"),
                     "reference_steps_per_s": statistics.median(rate[reference]),
                     "steps_per_s": statistics.median(rate[case]), "ratios": ratios,
                     "target": REGIME_TARGETS.get(case)})
    return rows


def format_regimes(rows: list[dict], blas_default: int) -> str:
    """The regime rows as a Markdown table (BLAS default: ``blas_default`` threads)."""
    lines = ["| case | reference | ref steps/s | steps/s | ratio min / median / max | target |",
             "| --- | --- | ---: | ---: | --- | --- |"]
    for row in rows:
        low, mid, high = min(row["ratios"]), statistics.median(row["ratios"]), max(row["ratios"])
        goal = row["target"]
        verdict = "" if goal is None else f">= {goal:.2f} " + ("ok" if mid >= goal else "LOW")
        case = row["case"].replace("default threads", f"default threads ({blas_default})")
        lines.append(f"| {case} | {row['reference']} | {row['reference_steps_per_s']:,.0f} | "
                     f"{row['steps_per_s']:,.0f} | {low:.3f} / {mid:.3f} / {high:.3f} | "
                     f"{verdict} |")
    return "\n".join(lines)


_FIRST_STEP = """
import time
import numpy as np
start = time.perf_counter()
import gymnasium as gym
import marine_envs
imported = time.perf_counter()
env = gym.make({env_id!r})
env.reset(seed=0)
system = env.unwrapped.system
env.step(system.actuation.nominal_action(system.model).astype(np.float32))
vec = gym.make_vec({env_id!r}, num_envs=4, vectorization_mode="vector_entry_point")
vec.reset(seed=0)
vec.step(np.zeros(vec.action_space.shape, dtype=np.float32))
print(imported - start, time.perf_counter() - imported)
"""


def compile_times(vehicles: list[str]) -> list[dict]:
    """Per vehicle: seconds of the import and of the first make + reset + step (single and
    vector env) in a fresh process, with an empty numba cache and then with the one it left."""
    rows = []
    for vehicle in vehicles:
        with tempfile.TemporaryDirectory() as cache:
            # threadpoolctl cannot reach a child process: its BLAS is pinned by the environment
            env = dict(os.environ, NUMBA_CACHE_DIR=cache, OPENBLAS_NUM_THREADS="1",
                       OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
            code = _FIRST_STEP.format(env_id=SHORT[vehicle])
            runs = [subprocess.run([sys.executable, "-c", code], env=env, check=True,
                                   capture_output=True, text=True).stdout.split()
                    for _ in range(2)]
        (imported, first), (_, cached) = ([float(v) for v in run] for run in runs)
        rows.append({"vehicle": vehicle, "import_s": imported, "first_use_s": first,
                     "cached_s": cached})
    return rows


def format_table(rows: list[dict]) -> str:
    """The throughput rows as a Markdown table, with the acceptance where the issue sets one."""
    lines = ["| vehicle | case | reference | ref steps/s | steps/s | ratio min / median / max "
             "| target |", "| --- | --- | --- | ---: | ---: | --- | --- |"]
    for row in rows:
        case = "single" if row["case"] == "single" else f"N={row['case']}"
        low, mid, high = min(row["ratios"]), statistics.median(row["ratios"]), max(row["ratios"])
        goal = target(row["vehicle"], row["case"])
        verdict = "" if goal is None else f">= {goal:.2f} " + ("ok" if mid >= goal else "LOW")
        lines.append(f"| {row['vehicle']} | {case} | {row['reference']} | "
                     f"{row['reference_steps_per_s']:,.0f} | {row['steps_per_s']:,.0f} | "
                     f"{low:.3f} / {mid:.3f} / {high:.3f} | {verdict} |")
    return "\n".join(lines)


def format_compile(rows: list[dict]) -> str:
    """The compile-time rows as a Markdown table."""
    lines = ["| vehicle | import, s | first use (empty cache), s | first use (cached), s |",
             "| --- | ---: | ---: | ---: |"]
    for row in rows:
        mark = "" if row["first_use_s"] < COMPILE_TARGET else f" (target < {COMPILE_TARGET:g})"
        lines.append(f"| {row['vehicle']} | {row['import_s']:.2f} | {row['first_use_s']:.1f}"
                     f"{mark} | {row['cached_s']:.2f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats (3)")
    parser.add_argument("--steps", type=int, default=2000,
                        help="steps per repeat for N <= 64; fewer for larger N, but at least "
                             "two blocks of the random streams (2000)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1, 64, 1024],
                        help="vector sizes N (1 64 1024)")
    parser.add_argument("--envs", nargs="+", default=list(SHORT), choices=list(SHORT),
                        help="vehicles (all)")
    parser.add_argument("--no-compile", action="store_true",
                        help="skip the compile-time table (two fresh processes per vehicle)")
    parser.add_argument("--no-regimes", action="store_true",
                        help="skip issue 59's regimes table (resets, BLAS threads, effects)")
    parser.add_argument("--regime-size", type=int, default=1024,
                        help="vector size N of the regimes table (1024)")
    parser.add_argument("--json", help="also write the results as JSON")
    add_docs_option(parser, "throughput")
    args = parser.parse_args(argv)
    check_page_path(parser, args.docs)
    warnings.filterwarnings("ignore")
    blas_default = blas_threads_now()
    with benchmark_run("throughput", argv) as bench:
        compiled = [] if args.no_compile else compile_times(args.envs)
        rows = measure(args.envs, args.sizes, args.steps, args.repeats)
        bench.show(format_table(rows), f"Steps per second against CartPole, {args.repeats} "
                   "interleaved repeats")
        paired = [] if args.no_regimes else regimes(args.regime_size, args.steps,
                                                    args.repeats, blas_default)
        if paired:
            print()
            bench.show(format_regimes(paired, blas_default), "Resets, BLAS threads "
                       f"and a diagnosed vessel, {args.repeats} interleaved repeats")
        if compiled:
            print()
            bench.show(format_compile(compiled), "First use of the compiled kernels")
    if args.json:
        write_json(args.json, {"throughput": rows, "regimes": paired, "compile": compiled})
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)


if __name__ == "__main__":
    main()
