"""RL against LQR on all five vehicles: LQR behind the true state, the raw sensors and the
``kf`` estimator; pure RL, residual RL (LQR plus a learned correction) and the recurrent
raw-sensor agent, each training seed its own row.

Every controller is scored on two evaluation sets, reported apart:

* TUNING seeds 1000-1009: the seeds settings were chosen on;
* HELD-OUT seeds, drawn fresh each run (printed; ``--held-out-first`` repeats a printed set)
  from [10**6, 2**31), never used to choose anything. The held-out set runs the registered
  sea, so its ratios compare with the tuning ones; ``--held-out-sea`` also draws a sea state
  (waves, current or wind) per vehicle unlike the registered one (printed).

Each episode is a full registered episode, all episodes of a set one batch
(``agents.evaluation.evaluate``). Every ratio is a mean cost over that of LQR behind ``kf`` on
the same vehicle and seeds. Verdicts follow issue 60's acceptance: pure RL passes within 25 % of
LQR; a residual agent must cost at most LQR's and differ from it (one within 0.5 % learnt
nothing); the best agent per vehicle must cost at most LQR's, and at most 0.95x on three
vehicles to be clearly better. An agent with a failed episode fails, whatever its cost.

Where the agents come from:

* default: the runs already in ``--runs DIR``, folders ``{Env}-{kind}-{estimator}-seed{seed}``
  (``marine train`` runs, e.g. ``ROV-residual_ppo-kf-seed1``); every kind found is scored, the
  missing ones of ``--agents`` x ``--seeds`` are listed;
* ``--train``: first trains the missing ones with the YAML's settings (``agents/hyperparams.yaml``;
  a residual kind adds ``residual: lqr``), pure and residual kinds behind ``--estimator``, a
  recurrent ``*_lstm`` kind on the raw sensors;
* ``--zoo``: the shipped agents, ``agents/zoo/{Env}-v0/{kind}/``.

    python benchmarks/rl_vs_lqr.py [--runs runs/rl_vs_lqr] [--train | --zoo]
        [--envs USV ROV ...] [--agents ppo residual_ppo ppo_lstm] [--seeds 0 1]
        [--episodes 10] [--held-out-episodes 10] [--held-out-first SEED] [--held-out-sea]
        [--json out.json] [--docs [PAGE]] [--figure PNG] [--readme README.md]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import re  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import _rl_vs_lqr_report as report  # noqa: E402
import numpy as np  # noqa: E402
from _common import REPO, Run, add_docs_option, benchmark_run, check_page_path  # noqa: E402

from agents import evaluation, sb3  # noqa: E402
from marine_envs import ENVIRONMENTS  # noqa: E402
from marine_envs.files import write_json, write_text  # noqa: E402

SHORT = {env_id.split("/")[1].removesuffix("-v0"): env_id for env_id in ENVIRONMENTS}
VEHICLES = list(SHORT)
TUNING_FIRST = 1000  # the tuning seeds: 1000, 1001, ...
HELD_OUT_LOW, HELD_OUT_HIGH = 10**6, 2**31  # the held-out seeds' range
LQR_ESTIMATORS = ("true", "raw", report.REFERENCE)
RUN_NAME = re.compile(r"^(?P<vehicle>[A-Za-z]+)-(?P<kind>\w+?)-(?P<estimator>[\w]+)"
                      r"-seed(?P<seed>\d+)$")
ZOO = REPO / "agents" / "zoo"
DEG = np.pi / 180
TITLE = "RL against LQR on all five vehicles"
ABOUT = __doc__.split("\n\n", 1)[1].split("\n    python")[0]


@dataclasses.dataclass(frozen=True)
class Contender:
    """A controller to score on one vehicle: LQR behind ``estimator`` (``source`` None) or a
    trained agent (``source``: its run folder, or a zoo name ``zoo:ROV-v0/ppo``)."""

    vehicle: str
    kind: str
    estimator: str
    seed: int | None = None
    source: Path | str | None = None
    training: dict[str, Any] = dataclasses.field(default_factory=dict, compare=False)


# -- which agents ---------------------------------------------------------------------------

def kind_of(config: dict[str, Any]) -> str:
    """A run's agent kind: its algorithm, ``residual_`` before it when its settings put an LQR
    inside (``hyperparams["residual"] == "lqr"``)."""
    residual = (config.get("hyperparams") or {}).get("residual") == "lqr"
    return f"residual_{config['algo']}" if residual else str(config["algo"])


def training_of(config: dict[str, Any]) -> dict[str, Any]:
    """The training record of a run's ``config.json`` (steps, wall time, steps/s, status)."""
    return {"timesteps": config.get("timesteps"), "wall_seconds": config.get("wall_seconds"),
            "steps_per_second": config.get("steps_per_second"),
            "status": config.get("status")}


def estimator_for(kind: str, estimator: str) -> str:
    """What an agent of ``kind`` is trained behind: a recurrent kind the raw sensors (it is the
    learned estimator), the others ``estimator``."""
    return "raw" if kind.endswith("_lstm") else estimator


def run_folder(runs: Path, vehicle: str, kind: str, estimator: str, seed: int) -> Path:
    return runs / f"{vehicle}-{kind}-{estimator}-seed{seed}"


def found_runs(runs: Path, vehicles: Sequence[str]) -> list[Contender]:
    """The trained runs in ``runs`` (folders named as :func:`run_folder` with a config.json
    and a model) of ``vehicles``, described by their config.json."""
    out = []
    for folder in sorted(runs.iterdir()) if runs.is_dir() else []:
        match = RUN_NAME.match(folder.name)
        if not match or match["vehicle"] not in vehicles or not (folder / "model.zip").exists():
            continue
        config = sb3.read_config(folder)
        out.append(Contender(match["vehicle"], kind_of(config), config.get("estimator") or "raw",
                             int(config["seed"]), folder, training_of(config)))
    return out


def zoo_agents(vehicles: Sequence[str]) -> list[Contender]:
    """The shipped agents (``agents/zoo/{Env}-v0/{kind}/``) of ``vehicles``."""
    out = []
    for vehicle in vehicles:
        for folder in sorted((ZOO / f"{vehicle}-v0").glob("*/config.json")):
            config = sb3.read_config(folder.parent)
            out.append(Contender(vehicle, kind_of(config), config.get("estimator") or "raw",
                                 int(config["seed"]),
                                 f"zoo:{vehicle}-v0/{folder.parent.name}", training_of(config)))
    return out


def wanted(vehicles: Sequence[str], kinds: Sequence[str], seeds: Sequence[int],
           estimator: str) -> list[tuple[str, str, str, int]]:
    """``(vehicle, kind, estimator, seed)`` of every run the comparison asks for."""
    return [(v, k, estimator_for(k, estimator), s) for v in vehicles for k in kinds
            for s in seeds]


def algo_and_overrides(kind: str) -> tuple[str, dict[str, Any]]:
    """The algorithm of a kind and the settings it adds to the YAML's."""
    if kind.startswith("residual_"):
        return kind.removeprefix("residual_"), {"residual": "lqr"}
    return kind, {}


def check_trainable(parser: argparse.ArgumentParser, kinds: Sequence[str], vehicles: Sequence[str],
                    estimator: str, timesteps: int | None) -> None:
    """Refuse a kind the settings refuse (an unknown algorithm, residual RL where this checkout
    has none) before training anything."""
    for kind in kinds:
        algo, overrides = algo_and_overrides(kind)
        for vehicle in vehicles:
            try:
                sb3.settings(SHORT[vehicle], algo, estimator_for(kind, estimator), timesteps,
                             hyperparams=overrides)
            except (ValueError, ImportError) as error:
                parser.error(f"--agents {kind} on {vehicle}: {error}")


def train_missing(missing: Sequence[tuple[str, str, str, int]], runs: Path,
                  timesteps: int | None) -> None:
    """Train each missing run into its folder, with the YAML's settings."""
    for vehicle, kind, estimator, seed in missing:
        algo, overrides = algo_and_overrides(kind)
        out = run_folder(runs, vehicle, kind, estimator, seed)
        print(f"training {out.name}", flush=True)
        sb3.train(SHORT[vehicle], algo, estimator, timesteps, out, seed=seed,
                  hyperparams=overrides or None, progress_bar=True)


# -- the evaluation sets ---------------------------------------------------------------------

def held_out_first(episodes: int, entropy: int) -> int:
    """The first held-out seed, from ``entropy`` (a fresh ``SeedSequence().entropy``): the set
    ``first, ..., first + episodes - 1`` lies in [10**6, 2**31)."""
    return HELD_OUT_LOW + entropy % (HELD_OUT_HIGH - HELD_OUT_LOW - episodes)


def draw_sea(vehicle: str, rng: np.random.Generator) -> dict[str, Any]:
    """A sea state (or current, or wind) for ``vehicle`` unlike the registered one, as its
    environment's keyword arguments in SI units (angles in rad)."""
    u = rng.uniform
    if vehicle == "USV":  # registered: hs 2 m, tp 8 s, waves from 60 deg
        return {"hs": u(1.0, 3.5), "tp": u(6.0, 11.0), "wave_heading": u(20, 160) * DEG}
    if vehicle == "Hydrofoil":  # registered: the hs schedule 0.10-0.30 m, waves from 120 deg
        from marine_envs.envs.hydrofoil import DEFAULT_HS_SCHEDULE

        scale = u(0.6, 1.5)
        return {"hs": [[t, hs * scale] for t, hs in DEFAULT_HS_SCHEDULE],
                "wave_heading": u(90, 180) * DEG}
    if vehicle == "ROV":  # registered: current (0.1, 0, 0) m/s, std 0.05 m/s
        return {"current": (u(0.0, 0.25), u(-0.15, 0.15), 0.0), "current_std": u(0.02, 0.1)}
    if vehicle == "DPVessel":  # registered: w0 (1.2, 1.0, 1.05) rad/s, sigma_eta (1, 1, 2 deg)
        from marine_envs.models.dp_vessel import DPVesselModel

        p = DPVesselModel().params
        return {"params": {"w0": [w * u(0.7, 1.3) for w in p.w0],
                           "sigma_eta": [s * u(0.5, 1.5) for s in p.sigma_eta],
                           "sigma_b": [s * u(0.5, 2.0) for s in p.sigma_b]}}
    if vehicle == "Hovercraft":  # registered: wind 5 m/s from 45 deg, gusts 1 m/s
        return {"wind_speed": u(2.0, 9.0), "wind_direction": u(0, 360) * DEG,
                "wind_gust": u(0.5, 2.0)}
    raise ValueError(f"vehicle={vehicle!r} is invalid: one of {VEHICLES}")


def describe_sea(sea: dict[str, Any]) -> str:
    """The keyword arguments, angles in degrees, three significant figures."""
    def text(key: str, value: Any) -> str:
        if isinstance(value, (list, tuple)):
            return "[" + ", ".join(text(key, v) for v in value) + "]"
        if isinstance(value, dict):
            return "{" + ", ".join(f"{k}: {text(k, v)}" for k, v in value.items()) + "}"
        if key in ("wave_heading", "wind_direction"):
            return f"{value / DEG:.0f} deg"
        return f"{value:.3g}"

    return ", ".join(f"{k}={text(k, v)}" for k, v in sea.items())


@dataclasses.dataclass(frozen=True)
class SeedSet:
    """An evaluation set: its name, seeds and sea per vehicle (the environments' keyword
    arguments; empty: the registered sea)."""

    name: str
    seeds: list[int]
    seas: dict[str, dict[str, Any]]
    about: str


# -- scoring ---------------------------------------------------------------------------------

def score(contender: Contender, seed_set: SeedSet, steps: int | None,
          progress: Callable[[int], None]) -> dict[str, Any]:
    """One row: the contender scored on the set's seeds (one batch) on its vehicle's sea."""
    policy: str | Callable[[Any], Any] = "lqr" if contender.source is None \
        else sb3.load_agent(contender.source)  # an agent is its own factory
    began = time.perf_counter()
    episodes = evaluation.evaluate(SHORT[contender.vehicle], policy, contender.estimator,
                                   seed_set.seeds, env_kwargs=seed_set.seas.get(contender.vehicle),
                                   max_episode_steps=steps, progress=progress)
    seconds = time.perf_counter() - began
    costs = np.array([e["cost"] for e in episodes])
    training = contender.training
    return {"vehicle": contender.vehicle, "kind": contender.kind,
            "estimator": contender.estimator, "seed": contender.seed,
            "source": None if contender.source is None else str(contender.source),
            "timesteps": training.get("timesteps"), "wall_seconds": training.get("wall_seconds"),
            "steps_per_second": training.get("steps_per_second"),
            "episodes": len(costs), "cost": float(costs.mean()),
            "std": float(costs.std(ddof=1)) if costs.size > 1 else 0.0,
            "failed": int(sum(e["failed"] for e in episodes)),
            "costs": costs.tolist(), "eval_seconds": seconds}


def score_set(contenders: Sequence[Contender], seed_set: SeedSet, steps: int | None
              ) -> tuple[list[dict[str, Any]], list[str]]:
    """Every contender on the set, under one progress bar (steps of the batch), the ratios to
    LQR behind kf and the verdicts filled in; and the LQRs that cannot run (LQR on the raw
    sensors where they are not model states, e.g. the DP vessel's total motion), with why."""
    from tqdm import tqdm

    length = {c.vehicle: evaluation.episode_steps(SHORT[c.vehicle], steps) for c in contenders}
    rows, impossible = [], []
    with tqdm(total=sum(length[c.vehicle] for c in contenders), unit="step",
              desc=seed_set.name, file=sys.stderr) as bar:
        for c in contenders:
            bar.set_postfix_str(f"{c.vehicle} {c.kind} {c.estimator}"
                                + ("" if c.seed is None else f" seed {c.seed}"))
            before = bar.n
            try:
                rows.append(score(c, seed_set, steps, bar.update))
            except ValueError as error:
                if c.source is not None or c.estimator == report.REFERENCE:
                    raise
                impossible.append(f"{c.vehicle}: LQR behind {c.estimator}: "
                                  f"{str(error).split(';')[0]}")
            bar.update(length[c.vehicle] - (bar.n - before))  # a batch that ended early
    reference = {r["vehicle"]: r["cost"] for r in rows
                 if r["kind"] == "lqr" and r["estimator"] == report.REFERENCE}
    for r in rows:
        r["ratio"] = r["cost"] / reference[r["vehicle"]]
        r["verdict"] = report.verdict(r)
    return rows, impossible


def contenders_of(vehicles: Sequence[str], agents: Sequence[Contender]) -> list[Contender]:
    """Per vehicle: LQR behind true, raw and kf, then its agents by kind and seed."""
    out = []
    for vehicle in vehicles:
        out += [Contender(vehicle, "lqr", estimator) for estimator in LQR_ESTIMATORS]
        out += sorted((a for a in agents if a.vehicle == vehicle),
                      key=lambda a: (report.family(a.kind), a.kind, a.seed))
    return out


def evaluation_times(rows: Sequence[dict[str, Any]], vehicles: Sequence[str]) -> str:
    """The wall time of evaluating one agent (all episodes of the set, one batch) per vehicle,
    mean and range over the agents, and LQR behind kf for scale."""
    lines = ["| vehicle | episodes | one agent (mean, range) | LQR behind kf |",
             "|---|---:|---|---:|"]
    for vehicle in vehicles:
        mine = [r for r in rows if r["vehicle"] == vehicle]
        agents = [r["eval_seconds"] for r in mine if r["kind"] != "lqr"]
        lqr = [r["eval_seconds"] for r in mine if r["kind"] == "lqr"
               and r["estimator"] == report.REFERENCE]
        spread = f"{np.mean(agents):.1f} s ({min(agents):.1f}-{max(agents):.1f} s)" \
            if agents else "-"
        lines.append(f"| {vehicle} | {mine[0]['episodes']} | {spread} | {lqr[0]:.1f} s |")
    return "\n".join(lines)


# -- the command -----------------------------------------------------------------------------

def parse(argv: Sequence[str]) -> tuple[argparse.ArgumentParser, argparse.Namespace]:
    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--train", action="store_true",
                        help="train the missing runs of --agents x --seeds into --runs first "
                             "(the YAML's settings; hours each)")
    source.add_argument("--zoo", action="store_true",
                        help="score the shipped agents (agents/zoo/) instead of --runs")
    parser.add_argument("--record", action="store_true",
                        help="with --zoo: write each shipped agent's measured ratios onto its "
                             "card (what 'marine zoo' lists)")
    parser.add_argument("--runs", type=Path, default=Path("runs/rl_vs_lqr"), metavar="DIR",
                        help="the run folders {Env}-{kind}-{estimator}-seed{seed} "
                             "(default runs/rl_vs_lqr)")
    parser.add_argument("--envs", nargs="+", default=VEHICLES, choices=VEHICLES,
                        help="vehicles (default all five)")
    parser.add_argument("--agents", nargs="+", default=["ppo", "residual_ppo", "ppo_lstm"],
                        metavar="KIND", help="agent kinds asked for: an algorithm "
                        f"({', '.join(sorted(sb3.ALGOS))}), or residual_ALGO "
                        "(default: ppo residual_ppo ppo_lstm)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1],
                        help="training seeds asked for (default 0 1)")
    parser.add_argument("--estimator", default=report.REFERENCE,
                        help="what pure and residual agents are trained behind (default kf)")
    parser.add_argument("--timesteps", type=int, default=None,
                        help="with --train: steps per run (default: the YAML's)")
    parser.add_argument("--episodes", type=int, default=10,
                        help="tuning episodes, seeds 1000 onwards (default 10)")
    parser.add_argument("--held-out-episodes", type=int, default=10,
                        help="held-out episodes (default 10)")
    parser.add_argument("--held-out-first", type=int, default=None, metavar="SEED",
                        help="the first held-out seed, to repeat a printed run (default: "
                             "drawn fresh); never to choose settings")
    parser.add_argument("--held-out-sea", action="store_true",
                        help="also draw a sea state per vehicle unlike the registered one for "
                             "the held-out set (printed); ratios then stand apart from tuning")
    parser.add_argument("--max-episode-steps", type=int, default=None, metavar="N",
                        help="shorter episodes for a quick check (default: the registered "
                             "length, which a comparison of record uses)")
    parser.add_argument("--json", metavar="PATH", help="also write everything as JSON")
    parser.add_argument("--figure", type=Path, default=None, metavar="PNG",
                        help="the figure (default with --docs: rl_vs_lqr.png beside the page)")
    parser.add_argument("--readme", type=Path, default=None, metavar="FILE",
                        help="rewrite the block between <!-- rl_vs_lqr:begin --> and "
                             "<!-- rl_vs_lqr:end --> in FILE with the summary")
    add_docs_option(parser, "rl_vs_lqr")
    return parser, parser.parse_args(argv)


def check(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse bad input before any work, naming it."""
    named = [name for name in sb3.estimator_choices() if name is not None]
    if args.estimator not in named:
        parser.error(f"--estimator {args.estimator!r}: one of {named}")
    unknown = [k for k in args.agents if algo_and_overrides(k)[0] not in sb3.ALGOS]
    if unknown:
        parser.error(f"--agents {' '.join(unknown)}: unknown kind(s); an algorithm "
                     f"({', '.join(sorted(sb3.ALGOS))}) or residual_ALGO")
    for option in ("episodes", "held_out_episodes", "max_episode_steps", "timesteps"):
        value = getattr(args, option)
        if value is not None and value < 1:
            parser.error(f"--{option.replace('_', '-')} must be >= 1")
    first = args.held_out_first
    if first is not None and not HELD_OUT_LOW <= first <= HELD_OUT_HIGH - args.held_out_episodes:
        parser.error(f"--held-out-first {first}: in [{HELD_OUT_LOW}, "
                     f"{HELD_OUT_HIGH - args.held_out_episodes}] (away from the tuning seeds)")
    if args.record and not args.zoo:
        parser.error("--record writes the shipped agents' cards: it needs --zoo")
    if args.readme is not None:
        try:
            report.check_markers(args.readme.read_text(encoding="utf-8"), str(args.readme))
        except (OSError, ValueError) as error:
            parser.error(f"--readme: {error}")
    check_page_path(parser, args.docs)


def seed_sets(args: argparse.Namespace) -> list[SeedSet]:
    """The tuning set and the held-out set (its seeds and, with --held-out-sea, its seas
    drawn from one fresh entropy, printed)."""
    entropy = int(np.random.SeedSequence().entropy)
    first = held_out_first(args.held_out_episodes, entropy) if args.held_out_first is None \
        else args.held_out_first
    rng = np.random.default_rng(first)  # --held-out-first repeats the seas too
    seas = {v: draw_sea(v, rng) for v in args.envs} if args.held_out_sea else {}
    tuning = SeedSet("tuning", list(range(TUNING_FIRST, TUNING_FIRST + args.episodes)), {},
                     "seeds settings were chosen on, registered sea")
    sea = "drawn seas" if seas else "registered sea"
    held = SeedSet("held-out", list(range(first, first + args.held_out_episodes)), seas,
                   f"drawn this run, never used to choose anything, {sea}")
    return [tuning, held]


def agents_to_score(parser: argparse.ArgumentParser, args: argparse.Namespace
                    ) -> tuple[list[Contender], list[str]]:
    """The agents and the names of the asked-for runs that are missing (trained first with
    --train); no agent at all is the parser's error."""
    if args.zoo:
        agents = zoo_agents(args.envs)
        if not agents:
            parser.error(f"--zoo: no shipped agent of {' '.join(args.envs)} in {ZOO}")
        return agents, []
    asked = wanted(args.envs, args.agents, args.seeds, args.estimator)
    missing = [a for a in asked if not (run_folder(args.runs, *a) / "model.zip").exists()]
    if args.train and missing:
        check_trainable(parser, sorted({k for _, k, _, _ in missing}), args.envs,
                        args.estimator, args.timesteps)
        train_missing(missing, args.runs, args.timesteps)
        missing = []
    agents = found_runs(args.runs, args.envs)
    if not agents:
        parser.error(f"no trained run of {' '.join(args.envs)} in {args.runs} (folders "
                     "{Env}-{kind}-{estimator}-seed{seed}); --train trains them")
    return agents, [run_folder(args.runs, *a).name for a in missing]


def announce(bench: Run, agents: Sequence[Contender], missing: Sequence[str],
             sets: Sequence[SeedSet]) -> None:
    """Print (and keep for the page) what is scored, what is missing and the seed sets."""
    if missing:
        bench.note(f"Missing runs (not scored): {', '.join(missing)}.")
    unfinished = [f"{a.source} ({a.training['status']})" for a in agents
                  if a.training.get("status") not in (None, sb3.COMPLETE)]
    if unfinished:
        bench.note(f"Scored though training did not finish: {', '.join(unfinished)}.")
    for s in sets:
        bench.note(f"{s.name.capitalize()} seeds {s.seeds[0]}-{s.seeds[-1]} ({s.about}).")
    bench.note(f"(--held-out-first {sets[1].seeds[0]} repeats this run's held-out set.)")
    for s in sets:
        for vehicle, sea in s.seas.items():
            bench.note(f"{s.name.capitalize()} sea of the {vehicle}: {describe_sea(sea)}.")
        if s.seas:
            bench.note("(The kf estimator is built from each environment's own disturbance "
                       "models, so it knows the drawn sea; the agents do not.)")


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser, args = parse(argv)
    check(parser, args)
    sets = seed_sets(args)
    agents, missing = agents_to_score(parser, args)
    import torch

    torch.set_num_threads(1)  # small MLPs: torch's threads only fight numpy's on 2 cores
    results: dict[str, Any] = {"missing": missing, "sets": {}}
    with benchmark_run("rl_vs_lqr", argv) as bench:
        announce(bench, agents, missing, sets)
        if args.max_episode_steps:
            bench.note(f"Episodes cut to {args.max_episode_steps} steps (--max-episode-steps): "
                       "a quick check, not the comparison of record.")
        contenders = contenders_of(args.envs, agents)
        for s in sets:
            rows, impossible = score_set(contenders, s, args.max_episode_steps)
            if impossible and s is sets[0]:
                bench.note(f"Not run: {'; '.join(impossible)}.")
            entries = report.summary(rows, args.envs)
            label = f"{s.name.capitalize()} seeds {s.seeds[0]}-{s.seeds[-1]}"
            print(f"\n## {label}", flush=True)
            bench.show(report.format_table(rows), label)
            bench.show(report.format_summary(entries), f"{label}: per vehicle")
            bench.show(evaluation_times(rows, args.envs),
                       f"{label}: evaluation wall time, all episodes in one batch")
            results["sets"][s.name] = {"seeds": s.seeds, "seas": s.seas, "rows": rows,
                                       "summary": entries}
        held = results["sets"]["held-out"]
        figure = args.figure or (args.docs.parent / "rl_vs_lqr.png" if args.docs else None)
        if figure is not None:
            report.plot(held["rows"], args.envs, "Cost over LQR behind kf, held-out seeds "
                        f"{held['seeds'][0]}-{held['seeds'][-1]}: each agent kind, each "
                        "training seed a point (x: a failed episode)", bench, figure)
    if args.json:
        write_json(args.json, results)
    if args.record:
        record_scores(results["sets"], bench.record["date"])
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    if args.readme is not None:
        write_readme(args.readme, held, bool(sets[1].seas), bench, args.docs)


def record_scores(sets: dict[str, Any], date: str) -> None:
    """Write each shipped agent's ratio to LQR behind kf on each set onto its card."""
    names = {"tuning": "tuning", "held-out": "held_out"}
    scores: dict[str, dict[str, Any]] = {}
    for name, found in sets.items():
        reference = {r["vehicle"]: r for r in found["rows"]
                     if r["kind"] == "lqr" and r["estimator"] == report.REFERENCE}
        for r in found["rows"]:
            if r["source"] is None or not sb3.is_zoo_name(r["source"]):
                continue
            lqr = reference[r["vehicle"]]
            scores.setdefault(r["source"], {})[names[name]] = {
                "seeds": found["seeds"], "cost_ratio": r["ratio"], "cost": r["cost"],
                "lqr_cost": lqr["cost"], "failed": r["failed"], "lqr_failed": lqr["failed"],
                "measured": date}
    for agent, measured in scores.items():
        sb3.zoo.record_scores(agent, measured)
        print(f"recorded the scores of {agent} on its card", flush=True)


def write_readme(path: Path, held: dict[str, Any], drawn_sea: bool, bench: Run,
                 page: Path | None) -> None:
    """Rewrite the block between the markers of ``path`` with the held-out summary."""
    where = "docs/results/rl_vs_lqr.md" if page is None else \
        os.path.relpath(page.resolve(), path.resolve().parent)
    block = report.readme_block(held["summary"], held["seeds"],
                                "drawn seas" if drawn_sea else "the registered sea", where,
                                bench.command, bench.record["date"])
    text = path.read_text(encoding="utf-8")
    write_text(path, report.replace_block(text, block, str(path)))
    print(f"wrote the rl_vs_lqr block of {path}", flush=True)


if __name__ == "__main__":
    main()
