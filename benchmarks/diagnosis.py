"""Mismatch diagnosis on its seeded acceptance set, against plain SINDy on the residuals, and
the time one diagnosis takes on one core.

1. Accuracy. :func:`estimators.diagnosis.cases.catalogue_cases` on all five vehicles: every
   :data:`~estimators.diagnosis.cases.TARGETS` entry (the catalogue effects each vehicle can
   show, sized by ``typical_effect`` at strength 0.3, the hydrofoil's state terms against its
   model's own forces, ``SIZED_AGAINST``; ``LEFT_OUT`` says which are not and why),
   two two-effect combinations per vehicle and six effect-free records (one with ``--quick``;
   a rate of 95 % needs more than the test suite's twelve), at sensor noise 5 % and 10 % of each
   channel's spread; 300 s closed-loop records at 10 Hz. Odd seeds record only some channels
   (``PARTIAL``: no sway speed, no roll rate, the DP vessel's position alone). ``--split``
   chooses the seeds: ``tuned`` (0 and 1, effect-free from 100; every threshold and setting of
   the diagnosis was chosen on the USV and hovercraft cases of these) or ``held-out`` (2 and 3,
   effect-free from 200; the default, and the rates to quote). Each case is diagnosed against
   its nominal model and scored: the per-case table, the confusion table (Markdown), the rates
   per vehicle and the acceptance rates against their targets:

   - right (the issue's criterion: ranked right with the key parameter within 30 %): at least
     90 % of the cases with effects;
   - ranked right (the true effect and target ranked first; both of a pair in the first two):
     at least 90 % of the cases with effects;
   - the matched finding's key parameter within 30 % of the truth (a change's time within 10 s):
     at least 90 % of the matched findings;
   - held-out improvement of the combined findings >= 30 %: at least 90 % of the cases with
     effects;
   - no finding of confidence >= 0.5 on an effect-free record: at least 95 % of them.

2. Baseline: plain SINDy on the residuals (pysindy; ``pip install -e ".[bench]"``) on the same
   records with effects. The measured channels (all states but the USV's sway speed ``v`` and
   what a partial record leaves out, held at their nominal values) are smoothed and
   differentiated with pysindy's smoothed finite difference (Savitzky-Golay, 11 samples); the
   residual ``x_dot - model.rhs(x, u)`` of each measured state is regressed by
   ``SINDy(optimizer=STLSQ(threshold), feature_library=PolynomialLibrary(degree=3))`` on the
   measured states with the inputs as control. So that one threshold serves every channel and
   vehicle, states and inputs are divided by their root-mean-square (not centred, so a monomial
   keeps its meaning) and each residual by the spread of its state's derivative. The answer is
   the term with the largest ``|coefficient| x RMS(term)`` (RMS, not std: a constant term has
   none) over all equations, named by :func:`~estimators.diagnosis.cases.sindy_term_to_effect`;
   for a pair, the two best distinct answers. Threshold 0.1: a sweep over 0.01-0.5 (both
   vehicles, seed 0, 5 %, 10 % and 20 % noise, single effects; ``--sindy-thresholds``) ranked no
   case right at any threshold, so the middle value is kept. Without any effect and without
   noise the residual is already 1.4-13 times the spread of the derivative it belongs to (USV:
   the unmeasured sway speed held at zero; hydrofoil: the stiff heave-pitch model evaluated on
   smoothed 10 Hz states, and the sea), while an effect is sized at 0.3 of it. On the
   hovercraft, every state measured, it ranks no case right either (2026-11-21, 5 % and 10 %
   noise). Its ranked-right rate is reported next to the diagnosis's on the same cases, per
   noise level (``--with-20`` adds 20 % noise for both).

3. Timing: a 10-minute record at 10 Hz of the USV with quadratic damping on r at 10 % noise,
   diagnosed in this process pinned to one CPU with one BLAS thread (target: 6 s, issue 23);
   as a same-run reference, one call of the nominal EKF + RTS smoother that starts every
   diagnosis (``estimators.diagnosis.residuals.estimate``) on the same record, and the ratio.
   ``--timing-only`` runs this row alone; its JSON holds the diagnosis itself
   (``Diagnosis.to_dict``), so that two versions of the code can be compared on it.

Exit code 1 when an acceptance rate or the time target is missed. Run time on 2 cores: about
5 min with ``--quick --vehicles usv``; 36-40 min with ``--no-pairs --effect-free 3`` (314 cases,
median 3.5-6.5 s a case but 31-33 s for the ROV and 13 s for the hydrofoil); more in full.

    python benchmarks/diagnosis.py [--split held-out|tuned] [--quick] [--vehicles usv,rov]
                                   [--noise 0.05,0.10] [--seeds 2,3] [--no-pairs]
                                   [--effect-free N] [--jobs N] [--with-20] [--json out.json]
                                   [--docs [PAGE]]
    python benchmarks/diagnosis.py --timing-only [--json out.json] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from contextlib import nullcontext  # noqa: E402
from types import ModuleType  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from _common import add_docs_option, benchmark_run, check_page_path, pin_to_one_cpu  # noqa: E402
from numpy.typing import NDArray  # noqa: E402
from tqdm import tqdm  # noqa: E402

from estimators.diagnosis.cases import (  # noqa: E402
    ACCEPTANCE_VEHICLES,
    EFFECT_FREE_SEED,
    HELD_OUT_SEEDS,
    TUNED_SEEDS,
    Case,
    Outcome,
    catalogue_cases,
    confusion,
    run_case,
    sindy_term_to_effect,
    summarize,
    term_factors,
)
from estimators.diagnosis.synthetic import synthesize, typical_effect  # noqa: E402
from marine_envs.files import write_json  # noqa: E402
from marine_envs.models import VehicleModel, get_model  # noqa: E402
from marine_envs.recording import Recording  # noqa: E402

FloatArray = NDArray[np.float64]
#: STLSQ threshold of the SINDy baseline (on the scaled problem, see the module docstring).
SINDY_THRESHOLD = 0.1
#: Channels that are angles: unwrapped before differentiation.
ANGLES = ("psi", "phi", "theta")
#: The timing row: record length, s, and the target for one diagnosis, s.
TIMING_DURATION, TIMING_TARGET = 600.0, 6.0
Ranking = list[tuple[str, str, dict[str, str]]]
TITLE = "Mismatch diagnosis: acceptance set and time"
ABOUT = """\
The mismatch diagnosis (`estimators.diagnosis.diagnose`) on its seeded acceptance set: every
catalogue effect each vehicle can show, sized at 30 % of the disturbed quantity's spread,
hidden in 300 s closed-loop records at 10 Hz with sensor noise of 5 % and 10 % of each
channel's spread (odd seeds record only some channels), plus effect-free records; each case is
diagnosed against its nominal model and scored (ranked right, key parameter within 30 %,
held-out improvement, no confident finding on an effect-free record), next to plain SINDy on
the residuals of the same records. Every threshold of the diagnosis was chosen on seeds 0 and
1; seeds 2 and 3 are held out. The timing row is one diagnosis of a 10-minute USV record on one
core with one BLAS thread, against one call of the nominal EKF and RTS smoother that starts
every diagnosis, timed in the same process: the ratio is the result, the seconds depend on the
machine's load."""


# -- the SINDy baseline ---------------------------------------------------------------------------
def import_pysindy() -> ModuleType:
    """pysindy, or exit with how to install it."""
    try:
        import pysindy
    except ImportError:
        sys.exit('the SINDy baseline needs pysindy: pip install -e ".[bench]" (or pass --no-sindy)')
    return pysindy


def sindy_applicable(model: str) -> bool:
    """Whether every measured channel of ``model`` is one of its states."""
    vehicle = get_model(model)
    channels = getattr(vehicle, "measured_names", vehicle.state_names)
    return set(channels) <= set(vehicle.state_names)


def _rms(a: FloatArray) -> FloatArray:
    return np.sqrt(np.mean(a**2, axis=0)) + 1e-300


def sindy_ranking(recording: Recording, vehicle: VehicleModel, threshold: float,
                  keep: int = 2) -> Ranking:
    """The ``keep`` best distinct catalogue answers of plain SINDy on the residuals of
    ``recording`` (measured channels all states; see the module docstring)."""
    ps = import_pysindy()
    channels = list(recording.measured_names)
    y = recording.measurements.copy()
    for j, name in enumerate(channels):
        if name in ANGLES:
            y[:, j] = np.unwrap(y[:, j])
    u = recording.inputs
    differentiate = ps.SmoothedFiniteDifference()
    x_dot = differentiate(y, t=recording.dt)
    x = differentiate.smoothed_x_
    full = np.tile(vehicle.x0, (len(y), 1))  # unmeasured states at their nominal value
    measured = [vehicle.state_names.index(c) for c in channels]
    full[:, measured] = x
    residual = x_dot - vehicle.rhs(full, u)[:, measured]
    xs, us = x / _rms(x), u / _rms(u)
    names = channels + list(vehicle.input_names)
    model = ps.SINDy(optimizer=ps.STLSQ(threshold=threshold),
                     feature_library=ps.PolynomialLibrary(degree=3))
    with warnings.catch_warnings():  # "eliminated all coefficients" is an answer here
        warnings.simplefilter("ignore", UserWarning)
        model.fit(xs, t=recording.dt, x_dot=residual / np.std(x_dot, axis=0), u=us,
                  feature_names=names)
    columns = dict(zip(names, np.hstack([xs, us]).T, strict=True))
    terms = model.get_feature_names()
    size = np.array([1.0 if t == "1" else
                     _rms(np.prod([columns[f] for f in term_factors(t, names)], axis=0))
                     for t in terms])
    importance = np.abs(model.coefficients()) * size
    out: Ranking = []
    for flat in np.argsort(-importance, axis=None):
        i, k = np.unravel_index(flat, importance.shape)
        if importance[i, k] == 0 or len(out) == keep:
            break
        answer = sindy_term_to_effect(terms[k], channels[i], vehicle.state_names,
                                      vehicle.input_names)
        if answer[:2] not in [a[:2] for a in out]:
            out.append(answer)
    return out


def sindy_right(case: Case, ranking: Ranking) -> bool:
    """Every true effect (effect and target) among the first ``len(case.effects)`` answers."""
    top = [a[:2] for a in ranking[:len(case.effects)]]
    return all((e.effect, e.target) in top for e in case.effects)


# -- running the cases ----------------------------------------------------------------------------
def evaluate(case: Case, thresholds: Sequence[float]) -> tuple[Outcome, dict[float, bool]]:
    """Diagnose ``case`` and, where it applies, grade SINDy at each threshold on the same
    record (an empty dict where it does not)."""
    recording = case.recording()
    outcome = run_case(case, recording)
    if not (case.effects and thresholds and sindy_applicable(case.model)):
        return outcome, {}
    vehicle = get_model(case.model)
    return outcome, {th: sindy_right(case, sindy_ranking(recording, vehicle, th))
                     for th in thresholds}


def build_cases(vehicles: Sequence[str], noises: Sequence[float], seeds: Sequence[int],
                pairs: bool, effect_free: int, effect_free_seed: int,
                pool: ProcessPoolExecutor | None) -> list[Case]:
    """:func:`catalogue_cases` (odd seeds partially measured), one (vehicle, seed) per
    worker: sizing an effect runs a pilot simulation (~2 s)."""
    jobs = [dict(vehicles=(v,), noises=tuple(noises), seeds=(s,), pairs=pairs,
                 effect_free=effect_free if k == 0 else 0, effect_free_seed=effect_free_seed,
                 partial=True)
            for v in vehicles for k, s in enumerate(seeds)]
    if pool is None:
        return [c for job in jobs for c in catalogue_cases(**job)]
    futures = [pool.submit(catalogue_cases, **job) for job in jobs]
    return [c for f in futures for c in f.result()]


def run_cases(cases: Sequence[Case], thresholds: Sequence[float],
              pool: ProcessPoolExecutor | None) -> list[tuple[Outcome, dict[float, bool]]]:
    """:func:`evaluate` on every case (in the pool if any), in the cases' order."""
    bar = tqdm(total=len(cases), desc="diagnosing", unit="case")
    if pool is None:
        results = []
        for case in cases:
            results.append(evaluate(case, thresholds))
            bar.update()
    else:
        futures = {pool.submit(evaluate, case, thresholds): k for k, case in enumerate(cases)}
        results = [None] * len(cases)
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            bar.update()
    bar.close()
    return results


# -- the timing row -------------------------------------------------------------------------------
def timing(seed: int = 0) -> dict[str, Any]:
    """Seconds of one diagnosis of the 10-minute USV record and of one nominal smoother call,
    in this process pinned to one CPU, and the diagnosis (``Diagnosis.to_dict``)."""
    from estimators.diagnosis import diagnose
    from estimators.diagnosis.residuals import estimate

    pinned = pin_to_one_cpu()
    effect = typical_effect("usv", "quadratic_damping", "r", seed=seed, duration=TIMING_DURATION)
    recording = synthesize("usv", [effect], duration=TIMING_DURATION, noise=0.10, seed=seed)
    start = time.perf_counter()
    estimate(recording, get_model("usv"))
    smoother = time.perf_counter() - start
    start = time.perf_counter()
    diagnosis = diagnose(recording, "usv")
    seconds = time.perf_counter() - start
    return {"case": f"usv/quadratic_damping:r/noise=0.10/{TIMING_DURATION:.0f} s at 10 Hz",
            "seconds": seconds, "target": TIMING_TARGET, "passed": seconds <= TIMING_TARGET,
            "smoother_seconds": smoother, "ratio": seconds / smoother, "cpu": pinned,
            "diagnosis": diagnosis.to_dict()}


# -- reports --------------------------------------------------------------------------------------
def _flag(value: bool | None) -> str:
    return "-" if value is None else ("yes" if value else "NO")


def format_cases(outcomes: Sequence[Outcome]) -> str:
    """One line per case: the checks, the top findings and the time."""
    width = max([len(o.case) for o in outcomes] + [4]) + 2
    lines = [f"{'case':<{width}}{'ranked':>7}{'param':>6}{'impr.':>7}{'s':>6}  top findings",
             "-" * (width + 90)]
    for o in outcomes:
        impr = "-" if o.improvement is None else f"{o.improvement:.0%}"
        ok = o.ranked_right if o.true else not o.false_alarm
        top = ", ".join(f"{f} ({c:.2f})" for f, c in zip(o.found[:3], o.confidences,
                                                          strict=False))
        note = top or (o.reason[:60] if o.reason else "none")
        lines.append(f"{o.case:<{width}}{_flag(ok):>7}{_flag(o.parameter_ok):>6}{impr:>7}"
                     f"{o.seconds:>6.1f}  {note}")
    return "\n".join(lines)


def format_per_vehicle(outcomes: Sequence[Outcome]) -> str:
    """Per vehicle (full and partial channels together): each acceptance rate as
    ``passed/applicable`` and the median time per case."""
    lines = [f"{'vehicle':<12}{'right':>8}{'ranked right':>14}{'parameter':>11}"
             f"{'improvement':>13}{'clean':>8}{'median s':>10}", "-" * 76]
    for model in dict.fromkeys(o.model for o in outcomes):
        mine = [o for o in outcomes if o.model == model]
        rates = summarize(mine)
        cells = "".join(f"{_count(rates[k]):>{w}}" for k, w in (
            ("right", 8), ("ranked_right", 14), ("parameter_ok", 11), ("improvement_ok", 13),
            ("clean", 8)))
        lines.append(f"{model:<12}{cells}{np.median([o.seconds for o in mine]):>10.1f}")
    return "\n".join(lines)


def _count(row: dict[str, Any]) -> str:
    return "-" if row["rate"] is None else f"{round(row['rate'] * row['n'])}/{row['n']}"


def format_confusion(table: dict[str, dict[str, int]]) -> str:
    """The confusion table in Markdown: true effect (rows) by found effect (columns)."""
    found = sorted({f for row in table.values() for f in row}, key=lambda f: (f == "none", f))
    lines = ["| true \\ found | " + " | ".join(found) + " |",
             "|---|" + "---:|" * len(found)]
    for truth in sorted(table, key=lambda t: (t == "none", t)):
        cells = [str(table[truth].get(f, "")) for f in found]
        lines.append(f"| {truth} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_named(outcomes: Sequence[Outcome]) -> str:
    """How often a miss at least named the truth: the true effects among the findings or
    among the terms reported as supported equally well (not an acceptance rate)."""
    effects = [o for o in outcomes if o.true]
    named = [o for o in effects
             if all(t in o.found[:len(o.true)] or t in o.alternatives for t in o.true)]
    beside = sum(not o.ranked_right for o in named)
    return (f"info  true effects found or named as equally supported: {len(named)} of "
            f"{len(effects)} ({beside} of them only as an alternative to the top finding)")


def format_acceptance(summary: dict[str, dict[str, Any]], time_row: dict | None) -> str:
    labels = {"right": "right: effect, target, key parameter",
              "ranked_right": "ranked right (cases with effects)",
              "parameter_ok": "key parameter within 30 % (matched)",
              "improvement_ok": "held-out improvement >= 30 % (effects)",
              "clean": "effect-free records without a false alarm"}
    lines = []
    for key, row in summary.items():
        rate = "n/a" if row["rate"] is None else f"{row['rate']:.0%}"
        lines.append(f"{'pass' if row['passed'] else 'FAIL':<6}{labels[key]:<44}{rate:>6} of "
                     f"{row['n']:<4} target >= {row['target']:.0%}")
    if time_row:
        t = time_row
        what = "one diagnosis, 10 min record, one core"
        lines.append(f"{'pass' if t['passed'] else 'FAIL':<6}{what:<44}{t['seconds']:>5.1f} s"
                     f"      target <= {t['target']:.0f} s; nominal smoother "
                     f"{t['smoother_seconds']:.1f} s (x{t['ratio']:.1f}), {t['cpu']}")
    return "\n".join(lines)


def compare(cases: Sequence[Case], results: Sequence[tuple[Outcome, dict[float, bool]]],
            thresholds: Sequence[float]) -> list[dict[str, Any]]:
    """Ranked-right rates of the diagnosis and of SINDy (each threshold) on the same cases
    (with effects, SINDy applicable), per noise level."""
    rows = []
    for noise in sorted({c.noise for c in cases}):
        same = [(o, s) for c, (o, s) in zip(cases, results, strict=True)
                if c.noise == noise and s]
        if not same:
            continue
        row = {"noise": noise, "n": len(same),
               "diagnosis": sum(o.ranked_right for o, _ in same) / len(same)}
        row["sindy"] = {th: sum(s[th] for _, s in same) / len(same) for th in thresholds}
        rows.append(row)
    return rows


def format_comparison(rows: Sequence[dict[str, Any]]) -> str:
    thresholds = list(rows[0]["sindy"]) if rows else []
    head = "".join(f"{'SINDy ' + format(th, 'g'):>14}" for th in thresholds)
    lines = [f"{'noise':<8}{'cases':>6}{'diagnosis':>11}{head}", "-" * (25 + 14 * len(thresholds))]
    for row in rows:
        cells = "".join(f"{row['sindy'][th]:>14.0%}" for th in thresholds)
        lines.append(f"{row['noise']:<8.2f}{row['n']:>6}{row['diagnosis']:>11.0%}{cells}")
    return "\n".join(lines)


# -- main -----------------------------------------------------------------------------------------
def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v]


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="one seed, no pairs, one effect-free record per vehicle and noise")
    parser.add_argument("--vehicles", default=",".join(ACCEPTANCE_VEHICLES),
                        help="comma-separated models (%(default)s)")
    parser.add_argument("--noise", default="0.05,0.10",
                        help="comma-separated sensor noise fractions (0.05,0.10)")
    parser.add_argument("--split", choices=("tuned", "held-out"), default="held-out",
                        help="the cases the diagnosis was tuned on (seeds "
                        f"{','.join(map(str, TUNED_SEEDS))}) or the held-out ones (seeds "
                        f"{','.join(map(str, HELD_OUT_SEEDS))}; default); odd seeds record "
                        "only some channels")
    parser.add_argument("--seeds", help="comma-separated seeds (default: the split's)")
    parser.add_argument("--no-pairs", action="store_true", help="no two-effect cases")
    parser.add_argument("--effect-free", type=int, metavar="N",
                        help="effect-free records per vehicle and noise (6; 1 with --quick)")
    parser.add_argument("--with-20", action="store_true",
                        help="also 20 %% noise, both methods, in the comparison only "
                        "(not in the acceptance rates)")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                        help="worker processes (os.cpu_count(); 1: run in this process)")
    parser.add_argument("--no-sindy", action="store_true", help="skip the SINDy baseline")
    parser.add_argument("--sindy-thresholds", default=str(SINDY_THRESHOLD),
                        help=f"comma-separated STLSQ thresholds to report ({SINDY_THRESHOLD})")
    parser.add_argument("--no-timing", action="store_true", help="skip the timing row")
    parser.add_argument("--timing-only", action="store_true",
                        help="only the timing row (no cases, no SINDy)")
    parser.add_argument("--json", help="also write the outcomes, rates and timing as JSON")
    return parser


def main_timing(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """The timing row alone (``--timing-only``), its JSON and its page."""
    with benchmark_run("diagnosis", argv) as bench:
        row = timing()
        bench.show(format_acceptance({}, row), "One diagnosis of a 10-minute record",
                   markdown=False)
    if args.json:
        write_json(args.json, {"timing": row, "passed": row["passed"]}, default=str)
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    return 0 if row["passed"] else 1


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    add_docs_option(parser, "diagnosis")
    args = parser.parse_args(argv)
    check_page_path(parser, args.docs)
    if args.timing_only:
        return main_timing(args, argv)
    thresholds = [] if args.no_sindy else _floats(args.sindy_thresholds)
    if thresholds:
        import_pysindy()  # fail before the long part
    vehicles = [v for v in args.vehicles.split(",") if v]
    noises = _floats(args.noise)
    held_out = args.split == "held-out"
    seeds = [int(s) for s in args.seeds.split(",") if s] if args.seeds else \
        list(HELD_OUT_SEEDS if held_out else TUNED_SEEDS)
    seeds = seeds[:1 if args.quick else None]
    extra = [0.20] if args.with_20 and 0.20 not in noises else []
    pairs = not (args.quick or args.no_pairs)
    effect_free = args.effect_free if args.effect_free is not None else \
        (1 if args.quick else 6)
    free_seed = EFFECT_FREE_SEED + (100 if held_out else 0)
    with benchmark_run("diagnosis", argv) as bench:
        bench.note(f"{args.split} cases: vehicles {', '.join(vehicles)}; noise "
                   f"{', '.join(f'{n:g}' for n in noises + extra)}; seeds "
                   f"{', '.join(map(str, seeds))}; effect-free seeds from {free_seed}; "
                   f"{'pairs' if pairs else 'no pairs'}; {args.jobs} worker process(es).")
        with ProcessPoolExecutor(args.jobs) if args.jobs > 1 else nullcontext() as pool:
            cases = build_cases(vehicles, noises + extra, seeds, pairs, effect_free, free_seed,
                                pool)
            results = run_cases(cases, thresholds, pool)
        outcomes = [o for o, _ in results]
        accepted = [o for c, o in zip(cases, outcomes, strict=True) if c.noise not in extra]
        bench.show(format_cases(outcomes), "Every case", markdown=False)
        print()
        bench.show(format_confusion(confusion(accepted)), "Confusion: true effect by top "
                   f"finding, noise {', '.join(f'{n:.2f}' for n in noises)}")
        print()
        comparison = compare(cases, results, thresholds) if thresholds else []
        if comparison:
            bench.show(format_comparison(comparison), "Ranked right: the diagnosis against "
                       "plain SINDy on the residuals, same cases", markdown=False)
            print()
        time_row = None if args.no_timing else timing()
        summary = summarize(accepted)
        bench.show(format_per_vehicle(accepted), "Per vehicle", markdown=False)
        print()
        bench.show(f"{format_acceptance(summary, time_row)}\n{format_named(accepted)}",
                   "Acceptance", markdown=False)
        print(f"\n{len(cases)} cases in {time.perf_counter() - bench.started:.0f} s")
    passed = all(r["passed"] for r in summary.values()) and (time_row or {}).get("passed", True)
    if args.json:
        write_json(args.json, {"settings": vars(args),
                               "outcomes": [dataclasses.asdict(o) for o in outcomes],
                               "summary": summary, "confusion": confusion(accepted),
                               "sindy": comparison, "timing": time_row, "passed": passed},
                   default=str)
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
