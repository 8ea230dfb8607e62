"""The sea estimated online (``kf_sea``) against the sea known (``kf``) and the sea assumed.

``kf`` takes each wave channel's shaping filter from the env's own sea; ``kf_sea`` does not
know the sea and weighs a bank of such filters over a grid around the vehicle's design sea
(:mod:`estimators.sea_bank`). On seas that are not the design sea, nor on the bank's grid, each
vehicle runs a batch of boats under LQR (state feedback on the estimate, the same design behind
every filter) behind:

* ``kf``: the sea known (the filter of the episode's own sea);
* ``kf (design sea)``: the sea assumed, the filter of the registered default sea;
* ``kf_sea``: the sea estimated.

The table gives the wave channel's peak frequency (rad/s) each filter works with (the bank's:
its weighted estimate over the last third of the run, median over boats, and its worst boat),
the estimation error of the vehicle's states weighted by the task's state weights
(``sqrt(mean (x_hat - x)' Q (x_hat - x))``), and the mean LQR cost. The seas of the tuning set
are the ones the bank's memory (120 s) was looked at on; the held-out seas were not used to
choose anything. The hydrofoil's registered sea changes during the episode (Hs 0.1 -> 0.3 ->
0.15 m): ``docs/sea_estimate.png`` shows the bank following it.

    python benchmarks/sea_estimate.py [--boats 8] [--seconds 600] [--json out.json] [--docs [PAGE]]
                                      [--no-plot | --plot-only]
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
from _common import Run, add_docs_option, benchmark_run, check_page_path  # noqa: E402
from tqdm import tqdm  # noqa: E402

import marine_envs  # noqa: E402, F401  (registers the environments)
from agents import evaluation  # noqa: E402
from agents.lqr import LQRPolicy  # noqa: E402
from estimators import registry  # noqa: E402
from estimators.disturbance import disturbance_filter, disturbance_model  # noqa: E402
from estimators.sea_bank import vehicle_options  # noqa: E402
from marine_envs.files import write_json  # noqa: E402

TITLE = "The sea estimated online"
ABOUT = """How well the bank of sea filters (`kf_sea`, `estimators.sea_bank`) estimates a sea it
was not told, against the Kalman filter of the episode's own sea (`kf`) and the one of the
vehicle's design sea. On seas that are neither the design sea nor on the bank's grid, a batch
of boats of each vehicle runs under LQR (state feedback on the estimate, the same design behind
every filter). The table gives the wave channel's peak frequency each filter works with (the
bank's: its weighted estimate over the last third of the run, median over boats, and its worst
boat), the estimation error weighted by the task's state weights
(`sqrt(mean (x_hat - x)' Q (x_hat - x))`) and the mean LQR cost. The tuning seas are the ones
the bank's memory (120 s) was chosen on; the held-out seas chose nothing. The figure follows
the hydrofoil's registered sea, whose Hs ramps 0.1 -> 0.3 -> 0.15 m."""

# (vehicle, peak period s or None for the one-parameter PM, Hs m): none is the design sea
# (USV: Tp 8 s, Hs 2 m; hydrofoil: the PM of Hs 0.3 m, Tp 2.75 s) nor on the bank's grid
TUNING = [("USV", 6.1, 1.3), ("Hydrofoil", 2.3, 0.2)]
HELD_OUT = [("USV", 5.0, 0.9), ("USV", 11.5, 3.1), ("Hydrofoil", 1.9, 0.12),
            ("Hydrofoil", 4.1, 0.45)]
TUNING_SEED, HELD_OUT_SEED = 1000, 2000
FIGURE = Path(__file__).resolve().parents[1] / "docs" / "sea_estimate.png"


def _design_sea_filter(env: Any) -> Any:
    """The disturbance-model filter of the vehicle's registered default sea."""
    return disturbance_filter(gym.make(env.unwrapped.spec.id, **vehicle_options(env)))


registry.register("kf_design_sea", _design_sea_filter, "kf of the design sea")


def run(env_id: str, estimator: str, sea: dict[str, float], boats: int, steps: int,
        seed: int) -> dict[str, Any]:
    """LQR behind ``estimator`` for ``steps`` steps on ``boats`` boats (seeds ``seed, ...``):
    mean cost, weighted estimation error, and the bank's estimates over time (``kf_sea``)."""
    venv = evaluation.make_env(env_id, boats, estimator, env_kwargs=sea, max_episode_steps=steps)
    policy = LQRPolicy.for_env(venv, feedforward=False)
    system = venv.unwrapped.system
    q, n_x = np.asarray(system.task.q), len(system.model.state_names)
    obs, info = venv.reset(seed=seed)
    bank = getattr(venv, "estimator", None)
    errors, peaks, cost = [], [], np.zeros(boats)
    running, failed = np.ones(boats, dtype=bool), np.zeros(boats, dtype=bool)
    for k in range(steps):
        action, _ = policy.predict(obs, episode_start=np.full(boats, k == 0))
        obs, reward, term, trunc, info = venv.step(action)
        e = np.asarray(obs, dtype=float)[:, :n_x] - np.asarray(info["state"])
        errors.append(np.where(running, np.einsum("ni,i,ni->n", e, q, e), np.nan))
        cost -= np.where(running, reward, 0.0)
        if estimator == "kf_sea":
            peaks.append(next(v for name, v in bank.parameters.items() if name.endswith("_peak")))
        failed |= running & np.asarray(term)
        running &= ~(np.asarray(term) | np.asarray(trunc))
    venv.close()
    return {"cost": float(cost.mean()), "failed": int(failed.sum()),
            "error": float(np.sqrt(np.nanmean(errors))),
            "peaks": np.array(peaks) if peaks else None, "dt": system.dt}


def sea_peak(env_id: str, sea: dict[str, float]) -> float:
    """The peak frequency (rad/s) of the first wave channel's shaping filter of ``sea``."""
    peaks = disturbance_model(gym.make(env_id, **sea).unwrapped.system).wave_peaks
    return next(iter(peaks.values()))[0]


def case(vehicle: str, tp: float | None, hs: float, boats: int, seconds: float, seed: int,
         split: str) -> dict[str, Any]:
    env_id = f"marine_envs/{vehicle}-v0"
    sea = {"hs": hs, "tp": tp}
    dt = gym.make(env_id).unwrapped.system.dt
    steps = int(round(seconds / dt))
    runs = {name: run(env_id, name, sea, boats, steps, seed)
            for name in ("kf", "kf_design_sea", "kf_sea")}
    late = runs["kf_sea"]["peaks"][2 * steps // 3:]  # (steps/3, boats)
    per_boat = np.median(late, axis=0)
    truth = sea_peak(env_id, sea)
    design = sea_peak(env_id, {})
    return {"split": split, "vehicle": vehicle, "tp": tp, "hs": hs, "seed": seed, "boats": boats,
            "seconds": seconds, "peak_true": truth, "peak_design": design,
            "peak_estimated": float(np.median(per_boat)),
            "peak_error_median": float(np.median(np.abs(per_boat / truth - 1))),
            "peak_error_worst": float(np.max(np.abs(per_boat / truth - 1))),
            **{f"{name}_{key}": runs[name][key] for name in runs
               for key in ("cost", "error", "failed")}}


def format_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a Markdown table."""
    lines = ["| set | vehicle | sea (Tp s, Hs m) | peak: true | design sea | kf_sea (error "
             "median, worst boat) | estimation error kf / design / kf_sea | LQR cost kf / "
             "design / kf_sea |", "|---|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(
            f"| {r['split']} | {r['vehicle']} | {r['tp']}, {r['hs']} | {r['peak_true']:.2f} | "
            f"{r['peak_design']:.2f} ({r['peak_design'] / r['peak_true'] - 1:+.0%}) | "
            f"{r['peak_estimated']:.2f} ({r['peak_error_median']:.0%}, "
            f"{r['peak_error_worst']:.0%}) | {r['kf_error']:.3g} / "
            f"{r['kf_design_sea_error']:.3g} / {r['kf_sea_error']:.3g} | "
            f"{r['kf_cost']:.0f} / {r['kf_design_sea_cost']:.0f} / {r['kf_sea_cost']:.0f} |")
    return "\n".join(lines)


def plot_changing_sea(boats: int, bench: Run, path: Path = FIGURE) -> None:
    """The hydrofoil's registered sea (Hs 0.1 -> 0.3 -> 0.15 m over 600 s): the bank's peak
    estimate per boat against the peak of the sea of each moment's Hs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    env_id = "marine_envs/Hydrofoil-v0"
    schedule = gym.make(env_id).unwrapped.system.disturbances.sea.hs
    result = run(env_id, "kf_sea", {}, boats, 12000, HELD_OUT_SEED)
    t = np.arange(result["peaks"].shape[0]) * result["dt"]
    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.plot(t, result["peaks"], color="tab:blue", alpha=0.35, lw=0.8)
    ax.plot([], [], color="tab:blue", label=f"kf_sea, {boats} boats (seeds {HELD_OUT_SEED}-)")
    times = np.arange(0.0, t[-1] + 5.0, 5.0)  # Hs ramps between its plateaus
    heights = np.round(schedule(times), 4)
    level = {h: sea_peak(env_id, {"hs": h}) for h in np.unique(heights)}
    ax.plot(times, [level[h] for h in heights], color="k",
            label="the sea's own (of its Hs at each time)")
    ax.set(xlabel="time [s]", ylabel="wave channel's peak [rad/s]",
           title="Hydrofoil: the sea's peak estimated online as Hs goes 0.1 -> 0.3 -> 0.15 m")
    ax.legend(loc="upper right")
    fig.tight_layout()
    bench.figure(fig, path, "The hydrofoil's changing sea, its peak estimated online by each "
                 "boat's bank (blue) against the peak of the sea of each moment (black)", dpi=120)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--boats", type=int, default=8, help="boats per sea (default 8)")
    parser.add_argument("--seconds", type=float, default=600.0,
                        help="length of each run, s (default 600)")
    parser.add_argument("--json", metavar="PATH", help="also write the rows as JSON")
    parser.add_argument("--no-plot", action="store_true", help="skip docs/sea_estimate.png")
    parser.add_argument("--plot-only", action="store_true", help="only docs/sea_estimate.png")
    add_docs_option(parser, "sea_estimate")
    args = parser.parse_args(argv)
    if args.boats < 1 or not args.seconds > 0:
        parser.error("--boats must be >= 1 and --seconds > 0")
    check_page_path(parser, args.docs)
    with benchmark_run("sea_estimate", argv) as bench:
        rows = []
        if not args.plot_only:
            cases = [(*c, TUNING_SEED, "tuning") for c in TUNING] + \
                    [(*c, HELD_OUT_SEED, "held out") for c in HELD_OUT]
            rows = [case(v, tp, hs, args.boats, args.seconds, seed, split)
                    for v, tp, hs, seed, split in tqdm(cases, desc="seas", unit="sea")]
            bench.show(format_table(rows), f"{args.boats} boats per sea, {args.seconds:g} s each")
        if not args.no_plot:
            plot_changing_sea(args.boats, bench)
    if args.json:
        write_json(args.json, {"rows": rows})
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)


if __name__ == "__main__":
    main()
