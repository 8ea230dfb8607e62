"""Joint state/parameter EKF throughput: the ROV's 13 states plus the morphing-robot patent's 18
drag coefficients, a batch of filters against the same filters run one by one, on one core.

Measured: env-updates per second, i.e. ``predict`` + ``update`` pairs times the number of
filters over the wall time, of :class:`~estimators.ekf.ExtendedKalmanFilter` on the ROV model
(central-difference state Jacobian and exact parameter Jacobian over the 31-dimensional
augmented state, RK4 mean) with DVL, gyro and depth measurements (10 channels) at 10 Hz, on both
of its paths: the compiled one (:mod:`estimators.ekf.kernels`, what ``from_model`` gives) and
the numpy one (``compiled=False``, the reference, which the compiled path replaced). The data: one
closed-loop run of ROV-v0 under LQR on the true state through the morph, with a fresh noise
realisation per filter. Rows: one filter (``N=1``) in a Python loop, the reference of the ratio;
batches of ``N = 64, 256, 1024``; each on both paths.

Absolute rates on shared machines are noise; ratios measured in the same run are the numbers to
compare. Each figure is the best of interleaved repeats. BLAS threads are limited to one
(threadpoolctl) and the process is pinned to one CPU.

Checks (exit code 1 when one fails): every row of a batch gives the estimate and covariance of
its filter run alone, within 1e-7 relative (the numpy path evaluates the model on a batch: its
rounding differs by ~1e-16, which the finite-difference Jacobians amplify by 1/step = 1e6; the
compiled path runs each filter alone and is exact); and the compiled path's estimates are the
numpy path's over the whole record, within 1e-6 of their standard deviations and its covariances
within 1e-8 of their largest entry.

    python benchmarks/ekf_throughput.py [--quick] [--repeats 3] [--json out.json] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from _common import add_docs_option, benchmark_run, check_page_path, pin_to_one_cpu  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

import marine_envs  # noqa: E402, F401 - registers the environments
from agents.lqr import LQRPolicy  # noqa: E402
from estimators.ekf import ExtendedKalmanFilter  # noqa: E402
from marine_envs.files import write_json  # noqa: E402
from marine_envs.models.rov import SEED_COEFFICIENTS, ROVModel  # noqa: E402

Array = NDArray[np.float64]
DT = 0.1
MEASURED = ("u", "v", "w", "phi", "theta", "psi", "p", "q", "r", "z")
NOISE = np.array([0.01, 0.01, 0.01, *np.radians([0.05] * 3), *np.radians([0.01] * 3), 0.02])
BATCHES = (64, 256, 1024)
#: issue 23: the compiled batch of 256 at least 5e4 env-updates/s; issue 5: at least 5x the loop
#: (of its own path); goal 1.5e5 env-updates/s
TARGET_RATE, TARGET_RATIO, GOAL_RATE = 5e4, 5.0, 1.5e5
PATHS = ("compiled", "numpy")
#: the compiled path against the numpy one: estimates in their standard deviations, covariances
#: relative to their largest entry
AGREEMENT = (1e-6, 1e-8)
TITLE = "Joint state and parameter EKF throughput"
ABOUT = """\
Env-updates per second (`predict` + `update` pairs times the number of filters, over the wall
time) of `estimators.ekf.ExtendedKalmanFilter` estimating the ROV's 13 states and the
morphing-robot patent's 18 drag coefficients jointly (31 states, 10 measured channels: DVL,
gyro, depth, at 10 Hz), on a closed-loop record of ROV-v0 under LQR through the morph with a
fresh noise realisation per filter. Both of its paths are timed in the same run: the compiled
one (`estimators.ekf.kernels`, what `from_model` gives) and the numpy one it replaced. The
ratios are the result: "vs loop" to one filter of the same path run in a Python loop, "vs numpy"
to the numpy path at the same N; absolute rates on a shared machine are not. Each figure is the
best of interleaved repeats, on one BLAS thread and one CPU. The checks: a batch's rows equal
their filters run alone, and the two paths agree over the whole record."""


def closed_loop_record(steps: int, seed: int = 0) -> tuple[Array, Array, Array]:
    """Applied forces ``(T, 6)``, true outputs ``(T, 10)`` and morph command ``(T,)`` of ROV-v0
    under LQR on the true state, morphing at 5 s."""
    env = gym.make("marine_envs/ROV-v0", morph_time=5.0, max_episode_steps=steps)
    policy = LQRPolicy.for_env(env, observed="state")
    _, info = env.reset(seed=seed)
    forces, outputs, s_cmd = [], [], []
    for _ in range(steps):
        outputs.append(info["state"][[ROVModel.state_names.index(c) for c in MEASURED]])
        s_cmd.append(info["disturbance"][3])
        action, _ = policy.predict(info["state"][None])
        _, _, terminated, truncated, info = env.step(action[0])
        forces.append(info["action_applied"])
        if terminated:
            raise RuntimeError("the closed-loop record ended early")
    return np.array(forces), np.array(outputs), np.array(s_cmd)


def make_filter(batch: int, path: str = "compiled") -> ExtendedKalmanFilter:
    """The benchmark's joint EKF of ``batch`` filters on ``path`` (one of :data:`PATHS`)."""
    model = ROVModel()
    theta = np.array([getattr(model.params, n) for n in SEED_COEFFICIENTS])
    P0 = np.diag(np.r_[np.full(13, 1e-2), (0.5 * np.abs(theta) + 0.1) ** 2])
    ekf = ExtendedKalmanFilter.from_model(
        model, DT, measured=MEASURED, Q=np.full(13, 1e-6), R=NOISE**2,
        parameters=SEED_COEFFICIENTS, parameter_noise=0.01 * np.abs(theta), P0=P0,
        angular=["psi"], batch_size=batch, compiled=path == "compiled")
    if ekf.compiled != (path == "compiled"):
        raise RuntimeError(f"the {path} path was asked for but not given")
    return ekf


def run(ekf: ExtendedKalmanFilter, forces: Array, y: Array, s_cmd: Array) -> float:
    """Filter the record; returns the wall time, s."""
    start = time.perf_counter()
    for k in range(y.shape[0]):
        ekf.disturbance[:, 3] = s_cmd[k]
        ekf.update(y[k])
        ekf.predict(forces[k])
    return time.perf_counter() - start


def noisy(outputs: Array, batch: int, seed: int) -> Array:
    """Measurements ``(T, batch, 10)``: the outputs plus a fresh noise realisation per filter."""
    rng = np.random.default_rng(seed)
    return outputs[:, None, :] + NOISE * rng.normal(size=(outputs.shape[0], batch, len(NOISE)))


def measure(record: tuple[Array, Array, Array], steps: dict[int, int], loop_filters: int,
            repeats: int, paths: tuple[str, ...] = PATHS) -> list[dict]:
    """Best-of-``repeats`` env-updates/s of the loop (``loop_filters`` filters of N=1) and of
    each batch, on each path, interleaved; ``ratio``: to the loop of the same path."""
    forces, outputs, s_cmd = record
    best: dict[tuple[str, int], float] = {}
    for _ in range(repeats):
        for path in paths:
            for batch, n_steps in steps.items():
                count = loop_filters if batch == 1 else 1
                y = noisy(outputs[:n_steps], batch * count, seed=batch)
                elapsed = 0.0
                for i in range(count):
                    elapsed += run(make_filter(batch, path), forces,
                                   y[:, i * batch:(i + 1) * batch], s_cmd)
                rate = batch * count * n_steps / elapsed
                best[path, batch] = max(best.get((path, batch), 0.0), rate)
    return [{"filter": f"EKF {path}, " + ("one filter in a loop" if batch == 1 else
                                          f"batch N={batch}"),
             "path": path, "N": batch, "env_updates_per_s": rate,
             "ratio": rate / best[path, 1]} for (path, batch), rate in best.items()]


def batch_equals_alone(record: tuple[Array, Array, Array], batch: int = 16, steps: int = 40,
                       rows: int = 3, path: str = "compiled") -> dict:
    """A batch's rows against the same filters run alone, on ``path``."""
    forces, outputs, s_cmd = record
    y = noisy(outputs[:steps], batch, seed=99)
    together = make_filter(batch, path)
    run(together, forces, y, s_cmd)
    worst = 0.0
    for i in range(rows):
        alone = make_filter(1, path)
        run(alone, forces, y[:, i:i + 1], s_cmd)
        for a, b in ((together.x[i], alone.x[0]), (together.P[i], alone.P[0])):
            worst = max(worst, float(np.abs(a - b).max() / np.abs(b).max()))
    return {"check": f"{path}: batch of {batch} = filters alone", "passed": worst < 1e-7,
            "detail": f"max relative difference {worst:.1e}"}


def compiled_equals_numpy(record: tuple[Array, Array, Array], batch: int = 8) -> dict:
    """The compiled path's estimates against the numpy path's over the whole record."""
    forces, outputs, s_cmd = record
    y = noisy(outputs, batch, seed=7)
    compiled, reference = make_filter(batch, "compiled"), make_filter(batch, "numpy")
    worst_x = worst_P = 0.0
    for k in range(y.shape[0]):
        for ekf in (compiled, reference):
            ekf.disturbance[:, 3] = s_cmd[k]
            ekf.update(y[k])
            ekf.predict(forces[k])
        std = np.sqrt(np.diagonal(reference.P, axis1=1, axis2=2))
        worst_x = max(worst_x, float((np.abs(compiled.x - reference.x) / std).max()))
        worst_P = max(worst_P, float((np.abs(compiled.P - reference.P).max(axis=(1, 2))
                                      / np.abs(reference.P).max(axis=(1, 2))).max()))
    return {"check": f"compiled = numpy path ({batch} filters)",
            "passed": worst_x < AGREEMENT[0] and worst_P < AGREEMENT[1],
            "detail": f"estimates within {worst_x:.1e} std, covariances {worst_P:.1e} relative",
            "estimates_in_std": worst_x, "covariances_relative": worst_P}


def format_table(rows: list[dict]) -> str:
    lines = [f"{'filter':<36}{'N':>6}{'env-updates/s':>16}{'vs loop':>10}{'vs numpy':>10}",
             "-" * 78]
    rate = {(row["path"], row["N"]): row["env_updates_per_s"] for row in rows}
    for row in rows:
        numpy_rate = rate.get(("numpy", row["N"])) if row["path"] != "numpy" else None
        speedup = f"{row['env_updates_per_s'] / numpy_rate:9.1f}x" if numpy_rate else ""
        lines.append(f"{row['filter']:<36}{row['N']:>6}{row['env_updates_per_s']:>16.3g}"
                     f"{row['ratio']:>9.1f}x{speedup:>10}")
    target = next((r for r in rows if r["N"] == 256 and r["path"] == "compiled"), None)
    if target is not None:
        value = target["env_updates_per_s"]
        lines += ["", f"issue 23: compiled N=256 >= {TARGET_RATE:.0e} env-updates/s: "
                  f"{'met' if value >= TARGET_RATE else 'MISSED'} ({value:.3g}/s); goal "
                  f"{GOAL_RATE:.1e}/s {'met' if value >= GOAL_RATE else 'missed'}",
                  f"issue 5: N=256 >= {TARGET_RATIO:g}x its loop: "
                  f"{'met' if target['ratio'] >= TARGET_RATIO else 'missed'} "
                  f"({target['ratio']:.1f}x; the compiled loop costs little more than Python's "
                  "overhead per call)"]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer steps (~20 s)")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved repeats (3)")
    parser.add_argument("--json", help="also write the rows and the checks as JSON")
    add_docs_option(parser, "ekf_throughput")
    args = parser.parse_args(argv)
    check_page_path(parser, args.docs)
    with benchmark_run("ekf_throughput", argv) as bench:
        pinned = pin_to_one_cpu()
        loop_filters, steps = (4, 40) if args.quick else (8, 200)
        record = closed_loop_record(steps)
        print(f"numpy {np.__version__}, {pinned}; best of {args.repeats}; {steps} steps; "
              f"loop of {loop_filters} filters")
        sizes = {1: steps, **{b: max(10, steps * 64 // b) for b in BATCHES}}
        rows = measure(record, sizes, loop_filters, args.repeats)
        bench.show(format_table(rows), f"Env-updates per second, best of {args.repeats}, "
                   f"{steps} steps", markdown=False)
        checks = [*(batch_equals_alone(record, path=path) for path in PATHS),
                  compiled_equals_numpy(record)]
        print()
        bench.show("\n".join(f"{'pass' if c['passed'] else 'FAIL':<6}{c['check']:<40}"
                             f"{c['detail']}" for c in checks), "Checks", markdown=False)
    if args.json:
        write_json(args.json, {"rows": rows, "checks": checks, "quick": args.quick})
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    return 0 if all(check["passed"] for check in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
