"""The ``marine`` command line: demo, simulate, episode, reproduce, diagnose, train, evaluate,
bench, envs."""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path

DESCRIPTION = """\
marine-envs: Gymnasium environments for marine vehicles in waves, seen through noisy, quantized
sensors; the literature's state estimators as wrappers; LQR and RL agents on the same cost.

Angles on the command line are in degrees; everything inside (and in recordings) is SI/radians.
"""

DIAGNOSE_DESCRIPTION = """\
Diagnose why a vehicle model and recordings of the vehicle disagree. Prints a summary and the
channel ranking; exit code 0 whether or not a mismatch is found (or the record is too short or
unexcited to judge: the reason is printed), 2 on invalid input.

two ways to judge (--method; auto picks free simulation for a series or a free decay, the
innovations otherwise):
  free          model tests (decays, zigzags, lab runs): the model is simulated freely over
                each whole record. --calibrate fits the named parameters by output error (from
                the record's own natural frequency and damping when it is a decay), with
                standard errors and an identifiability verdict; nested models (each candidate
                refitted with the calibrated parameters and the linear term it extends) are
                compared on held-out data: the last 30 % of one record, or each record of a
                series predicted by the model fitted on the others. Several recordings are one
                series: one parameter set, each its own initial state.
  innovations   records in a seaway: the nominal model's Kalman smoother estimates every
                state; its multi-step prediction errors locate the mismatch (channels, time
                windows, frequency band); every catalogue term is fitted to what the model
                cannot explain and kept only if it improves the predictions of the held-out
                last 30 % of the record significantly. Disturbance columns in the record (a
                logged wind, current or command: 'marine simulate --disturbances') are taken
                as known inputs; the filter estimates only the others.

catalogue (what a model may leave out):
  state terms   current, linear_damping, quadratic_damping, nonlinear_damping, coupling,
                nonlinear_restoring, parameter_change (a step at an unknown time),
                wave_frequency (a narrow-band oscillation), unlisted (a product of states or
                inputs no entry names)
  actuators     input_gain, input_delay, input_saturation, input_deadzone, input_rate_limit
  sensors       sensor_bias

the JSON (--json, or diagnosis.json in --report):
  model, mismatch (true / false / null = cannot judge), reason (when it cannot judge),
  channels [{name, score}] ranked by share of the excess prediction error,
  windows [{start, end, channel}] (s), band {low, high} (rad/s) or null,
  findings [{effect, target, parameters, std, confidence, improvement, explanation}],
  fit {method, before: {rmse}, after: {rmse}, improvement, validation, terms} (held-out, SI
  units), calibration (with --calibrate); free simulation adds calibration_quality {converged,
  parameters {name: {value, std, status}}, correlations}, model_check (the record's natural
  frequency and damping against the model's modes), unexplained {channel: {rmse,
  share_of_signal}}, alternatives (terms the data cannot tell apart, and the test that would),
  and each finding's standard_form (B1 B2 B3 damping, C1 C3 restoring, per unit inertia)
"""


BENCH_DESCRIPTION = """\
Run a grid of vehicles x estimators x sea states x sensor degradations x controllers x seeds.
Every controller is scored by the task's quadratic cost on the same seeded episodes; each cell
(all axes but the seed) runs its seeds as one batch. SB3 agents named in --controllers are
trained first, one per vehicle and estimator, on the moderate sea and default sensors, and
kept in DIR/agents. Finished cells are kept in DIR/rows.csv and not run again.

outputs (in --out):
  rows.csv, rows.parquet  a row per seed: vehicle, estimator, controller, sea, sensor, seed,
                          status (ok or n/a: why), cost, failed, seconds, rms_<state> and
                          rms_<input> (SI; _deg: degrees), saturated, estimation_rms_<state>
  summary.md              cost mean ± std per cell; the checks KF <= raw, true <= KF under LQR
  cost_by_estimator.png   cost by estimator per vehicle, a bar per controller
  degradation.png         cost against each degradation's level (if it has several levels)

on a Ray cluster: start it (ray start --head on one machine, ray start --address HEAD:6379 on
the others, each with marine-envs installed), then run on any of them:
  marine bench --backend ray --address auto --seeds 20 --sensors default noise=4 noise=16
(with --controllers ppo, --out must be on a filesystem all machines share: tasks save agents)
"""


def _demo(args: argparse.Namespace) -> int:
    from .demo import format_table, roll_reduction, run_demo

    plot = None if args.no_plot else args.plot
    summary = run_demo(seconds=args.seconds, seed=args.seed, hs=args.hs, plot=plot)
    print(f"USV-v0, Hs = {args.hs} m, stern-quartering sea, {args.seconds:g} s, seed {args.seed}")
    print(format_table(summary))
    print(f"LQR on the raw sensors reduces RMS roll by {roll_reduction(summary):.0%} "
          "(rudder-roll stabilisation) while holding the course.")
    if plot is not None:
        print(f"plot written to {plot}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=2)
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from marine_envs.recording import check_suffix, write_recording

    from .simulate import simulate

    check_suffix(args.out)
    env_kwargs = json.loads(args.env_kwargs) if args.env_kwargs else {}
    options = {k: v for k, v in (("amplitude", args.amplitude), ("period", args.period),
                                 ("hold", args.hold)) if v is not None}
    disturbances = [n.strip() for n in args.disturbances.split(",") if n.strip()]
    recording = simulate(args.env, args.steps, seed=args.seed, policy=args.policy,
                         env_kwargs=env_kwargs, progress=not args.quiet,
                         disturbances=disturbances, **options)
    path = write_recording(recording, args.out)
    print(f"wrote {len(recording.time)} samples ({recording.time[-1]:.1f} s) of model "
          f"{recording.model!r}: inputs {', '.join(recording.input_names)}; channels "
          f"{', '.join(recording.measured_names)}"
          + (f"; disturbances {', '.join(recording.disturbance_names)}"
             if recording.disturbance_names else "") + f" -> {path}")
    return 0


def _episode(args: argparse.Namespace) -> int:
    from .episode import run

    env_kwargs = json.loads(args.env_kwargs) if args.env_kwargs else {}
    summary = run(args.env, policy=args.policy, seconds=args.seconds, seed=args.seed,
                  env_kwargs=env_kwargs, plot=args.plot, estimator=args.estimator)
    on = f" on {args.estimator}" if args.estimator else ""
    print(f"{args.env}, policy {args.policy}{on}, seed {args.seed}")
    for key, value in summary.items():
        print(f"  {key:<24}{value:>14.6g}")
    if args.plot:
        print(f"plot written to {args.plot}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=2)
    return 0


def _reproduce(args: argparse.Namespace) -> int:
    from .reproduce import run

    result = run(args.name, quick=args.quick, progress=not args.quiet)
    print(result.text)
    if args.plot:
        result.plot(args.plot)
        print(f"plot written to {args.plot}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result.summary, f, indent=2, default=float)
        print(f"results written to {args.json}")
    return 0


def _envs(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from marine_envs import ENVIRONMENTS

    for env_id in ENVIRONMENTS:
        env = gym.make(env_id)
        sim = env.unwrapped.sim
        print(f"{env_id}\n  model {sim.model.name}: states {', '.join(sim.model.state_names)}; "
              f"inputs {', '.join(sim.model.input_names)}\n  observation "
              f"{', '.join(sim.sensors.channels)} {env.observation_space}\n  action "
              f"{env.action_space}, dt {sim.dt} s")
    return 0


def _diagnose(args: argparse.Namespace) -> int:
    from estimators.diagnosis import diagnose

    recordings = args.recording if len(args.recording) > 1 else args.recording[0]
    diagnosis = diagnose(recordings, args.model, params=args.params,
                         calibrate=args.calibrate or (), method=args.method,
                         log=lambda line: print(f"marine diagnose: {line}", file=sys.stderr))
    print(diagnosis.summary())
    if diagnosis.mismatch is False and diagnosis.reason:
        print(f"  reason: {diagnosis.reason}")
    if diagnosis.channels:
        if "score" in diagnosis.channels[0]:
            print("channels (share of the prediction error beyond sensor noise):")
            for channel in diagnosis.channels:
                print(f"  {channel['name']:<12}{channel['score']:>8.1%}")
        else:
            print("channels (held-out free-simulation RMS error of the nominal model, SI):")
            for channel in diagnosis.channels:
                print(f"  {channel['name']:<12}{channel['rmse']:>12.4g}")
    if args.json:
        diagnosis.to_json(args.json)
        print(f"diagnosis written to {args.json}")
    if args.report:
        from estimators.diagnosis.report import write_report

        path = write_report(diagnosis, args.report,
                            ", ".join(Path(r).name for r in args.recording))
        print(f"report written to {path}")
    return 0


def _train(args: argparse.Namespace) -> int:
    from .sb3 import train

    result = train(args.env_id, args.algo, args.estimator, args.timesteps, Path(args.out),
                   args.seed, args.n_envs, args.backend, progress_bar=not args.quiet)
    print(f"trained {result.timesteps} steps in {result.wall_seconds:.1f} s "
          f"({result.steps_per_second:.0f} steps/s); saved to {result.out}")
    if result.selected is not None:
        best = result.selected
        print(f"model.zip is the agent of {best['timesteps']} steps, the best on validation "
              f"({best['failed']} failed, mean cost {best['cost']:.4g}); the last is "
              "last_model.zip")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    import numpy as np

    from .sb3 import evaluate

    rows = evaluate(Path(args.dir), args.episodes, args.seed)
    print(f"{args.episodes} episodes, seeds {args.seed}..{args.seed + args.episodes - 1} "
          "(mean ± std; angles in degrees):")
    for key in rows[0]:
        if key != "seed":
            values = [row[key] for row in rows]
            print(f"  {key:28s} {np.mean(values):12.5g} ± {np.std(values):.3g}")
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows}, indent=2) + "\n")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from .benchmark import Grid, markdown_summary, run_grid, write_outputs, write_report

    chosen = {k: tuple(v) if isinstance(v, list) else v for k, v in vars(args).items()
              if k in GRID_OPTIONS and v is not None}
    grid = dataclasses.replace(Grid.quick(), **chosen) if args.quick else Grid(**chosen)
    out = Path(args.out)
    rows = run_grid(grid, out, args.backend, args.workers, args.address, not args.quiet)
    written = write_outputs(rows, out)
    print(markdown_summary(rows))
    if args.report:
        written.append(write_report(rows, out, Path(args.report), grid))
    if args.json:
        records = json.loads(rows.to_json(orient="records"))
        Path(args.json).write_text(json.dumps({"rows": records}, indent=1) + "\n")
        written.append(Path(args.json))
    print("wrote " + ", ".join(map(str, written)))
    return 0


GRID_OPTIONS = ("vehicles", "estimators", "controllers", "seas", "sensors", "seeds", "seconds",
                "timesteps")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="marine", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = commands.add_parser(
        "demo", help="a short USV episode: rudder fixed vs LQR; prints a table, writes a plot",
        description="Simulate the USV in a stern-quartering random sea with the rudder fixed and "
                    "with a discrete LQR autopilot acting on the noisy, quantized sensors; print "
                    "RMS heading, roll and rudder and the episode returns; write a plot.")
    demo.add_argument("--seconds", type=float, default=100.0, help="episode length, s (100)")
    demo.add_argument("--seed", type=int, default=0, help="episode seed (0)")
    demo.add_argument("--hs", type=float, default=2.0, help="significant wave height, m (2.0)")
    demo.add_argument("--plot", default="marine_demo.png", help="figure path (marine_demo.png)")
    demo.add_argument("--no-plot", action="store_true", help="do not write a figure")
    demo.add_argument("--json", metavar="PATH", help="also write the summary as JSON")
    demo.set_defaults(run=_demo)

    from .simulate import POLICIES

    sim = commands.add_parser(
        "simulate", help="record an episode (CSV or Parquet) in the recording format",
        description="Run an environment under an excitation signal or LQR and record time, "
                    "applied inputs and sensor outputs (SI units) with the model name and "
                    "parameters as metadata. The format follows the file suffix: .csv (with a "
                    ".csv.json sidecar) or .parquet (needs pyarrow).")
    sim.add_argument("--env", default="marine_envs/USV-v0", help="environment id")
    sim.add_argument("--steps", type=int, default=1000, help="number of samples (1000)")
    sim.add_argument("--seed", type=int, default=None, help="episode seed (random if omitted)")
    sim.add_argument("--out", required=True, help="output file, .csv or .parquet")
    sim.add_argument("--policy", choices=POLICIES, default="prbs",
                     help="excitation: zero, sine, random (held uniform levels), prbs (held "
                          "+-amplitude levels), or lqr (closed loop on the sensors; with "
                          "--amplitude, plus a random-step dither held --hold s: a closed-loop "
                          "identification experiment); default prbs")
    sim.add_argument("--amplitude", type=float, help="excitation amplitude, fraction of the "
                                                     "actuator range (0.3; lqr: none)")
    sim.add_argument("--period", type=float, help="sine period, s (20)")
    sim.add_argument("--hold", type=float, help="random/prbs hold time, s (5; lqr's dither 2)")
    sim.add_argument("--env-kwargs", metavar="JSON",
                     help='environment arguments, SI units, e.g. \'{"hs": 3.0, "tp": 9}\'')
    sim.add_argument("--disturbances", default="", metavar="NAMES",
                     help="comma-separated disturbance channels to record too (the model's "
                          "names, e.g. the ROV's morph command s_cmd or the hovercraft's "
                          "wind_north,wind_east): a diagnosis then takes them as known inputs")
    sim.add_argument("--quiet", action="store_true", help="no progress bar")
    sim.set_defaults(run=_simulate)

    from estimators import registry

    from .episode import EPISODE_ESTIMATORS, EPISODE_POLICIES

    episode = commands.add_parser(
        "episode", help="run one episode of any environment; print RMS errors, plot it",
        description="Run one episode of an environment and print its return and the RMS error "
                    "of every state the task weighs (angles in degrees); with --plot, draw the "
                    "true and measured states and the inputs against time.")
    episode.add_argument("env", help="environment id, e.g. marine_envs/ROV-v0")
    episode.add_argument("--policy", choices=EPISODE_POLICIES, default="lqr-state",
                         help="lqr-state (LQR on the true state, the default), lqr (on the raw "
                              "sensors), or an excitation: zero, sine, random, prbs")
    episode.add_argument("--estimator", choices=EPISODE_ESTIMATORS,
                         help="put an estimator between the sensors and the policy: "
                              f"{registry.describe()}; --policy lqr then acts on the full "
                              "estimated state")
    episode.add_argument("--seconds", type=float, help="episode length, s (the env's own)")
    episode.add_argument("--seed", type=int, default=0, help="episode seed (0)")
    episode.add_argument("--plot", metavar="PNG", help="write a figure of the episode")
    episode.add_argument("--env-kwargs", metavar="JSON",
                         help='environment arguments, SI units, e.g. \'{"zigzag": "20/20"}\'')
    episode.add_argument("--json", metavar="PATH", help="also write the summary as JSON")
    episode.set_defaults(run=_episode)

    from .reproduce import REPRODUCTIONS

    reproduce = commands.add_parser(
        "reproduce", help="re-run a source document's experiment and compare with its numbers",
        description="Re-run an experiment of the source documents: the document's own settings "
                    "and a corrected setting where the document's are degenerate (the output "
                    "says which is which and why), averaged over seeds with their spread.\n\n"
                    "  usv-quantized-observer  the USV observer patent: PD observer vs "
                    "Luenberger on quantized\n"
                    "                          USV data\n"
                    "  hydrofoil-akf           the hydrofoil AKF paper: LQR fed by a KF vs the "
                    "adaptive KF,\n"
                    "                          time-varying sea\n"
                    "  rov-online-id           the morphing-robot patent: joint EKF of velocity "
                    "and 18 drag\n"
                    "                          coefficients through the morph, thrust "
                    "feed-forward\n"
                    "  dp-wave-frequency       the DP wave-frequency patent: FFT + Butterworth + "
                    "EKF estimate of\n"
                    "                          the wave frequencies, wave filter update\n"
                    "  hovercraft-zigzag       the hovercraft EKF paper: staged EKF identification "
                    "from 5/5, 15/15,\n"
                    "                          25/25 zig-zags vs least squares",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    reproduce.add_argument("name", choices=REPRODUCTIONS, help="the experiment")
    reproduce.add_argument("--quick", action="store_true",
                           help="fewer seeds and a shorter run (seconds, for a smoke test)")
    reproduce.add_argument("--json", metavar="PATH", help="write the results as JSON")
    reproduce.add_argument("--plot", metavar="PNG", help="write the document-style figure")
    reproduce.add_argument("--quiet", action="store_true", help="no progress bar")
    reproduce.set_defaults(run=_reproduce)

    diagnose = commands.add_parser(
        "diagnose", help="find why a model and a recording disagree: which physics it lacks",
        description=DIAGNOSE_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    diagnose.add_argument("recording", nargs="+",
                          help="recording file(s) (.csv with its .json sidecar, or .parquet), "
                               "as written by 'marine simulate'; several: one series")
    diagnose.add_argument("--model", help="model name (default: the recording's metadata)")
    diagnose.add_argument("--params", metavar="FILE",
                          help='JSON object of nominal parameter overrides (names as in '
                               'docs/models.md, SI units), e.g. {"wn": 0.6}; applied on top of the '
                               "recording's metadata")
    diagnose.add_argument("--calibrate", metavar="P1,P2,...",
                          help="nominal parameters to fit first (comma-separated), so that "
                               "only what the model's structure leaves out remains")
    diagnose.add_argument("--method", choices=("auto", "free", "innovations"), default="auto",
                          help="free simulation (model tests) or filter innovations (seaway "
                               "records); default: auto (see above)")
    diagnose.add_argument("--json", metavar="OUT", help="write the diagnosis as JSON")
    diagnose.add_argument("--report", metavar="DIR",
                          help="write report.md, its PNG figures and diagnosis.json into DIR")
    diagnose.set_defaults(run=_diagnose)

    train = commands.add_parser(
        "train", help="train a Stable-Baselines3 agent (PPO, SAC, TD3, A2C) on an environment",
        description="Train an SB3 agent on the native batched environment, optionally behind "
                    "a state estimator. Hyperparameters per vehicle and algorithm come from "
                    "agents/hyperparams.yaml (RL-Zoo style); writes model.zip, config.json, "
                    "vecnormalize.pkl (if normalised) and checkpoints/ into --out. Where the "
                    "settings give validation_episodes, model.zip is the checkpoint that did "
                    "best on them (fewest failures, then least cost) and last_model.zip the "
                    "last.")
    train.add_argument("env_id", help="environment id, e.g. marine_envs/USV-v0")
    train.add_argument("--algo", default="ppo", help="ppo, sac, td3 or a2c (default ppo)")
    train.add_argument("--estimator", choices=registry.names(), metavar="ESTIMATOR",
                       help="what the agent sees: raw (the sensors, the default), true (the "
                            f"true state) or an estimator: {registry.describe()}")
    train.add_argument("--timesteps", type=int,
                       help="environment steps (default: the YAML's n_timesteps)")
    train.add_argument("--n-envs", type=int, help="boats stepped together (default: the YAML's)")
    train.add_argument("--backend", default="native",
                       help="native (our batched env) or dummy (SB3's DummyVecEnv)")
    train.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    train.add_argument("--out", required=True, metavar="DIR", help="output directory")
    train.add_argument("--quiet", action="store_true", help="no progress bar")
    train.set_defaults(run=_train)

    evaluate = commands.add_parser(
        "evaluate", help="evaluate an agent 'marine train' saved: cost and errors over seeded "
                         "episodes",
        description="Run the agent over seeded episodes behind its training estimator and print "
                    "the task's quadratic cost, failures, RMS errors of the weighted states and "
                    "inputs (angles in degrees), the fraction of saturated steps and the "
                    "estimator's RMS errors, as mean ± std over the episodes.")
    evaluate.add_argument("dir", help="the directory 'marine train --out' wrote")
    evaluate.add_argument("--episodes", type=int, default=5, help="episodes (default 5)")
    evaluate.add_argument("--seed", type=int, default=0,
                          help="first episode's seed; the others follow (default 0)")
    evaluate.add_argument("--json", metavar="PATH", help="also write {\"rows\": [...]} as JSON")
    evaluate.set_defaults(run=_evaluate)

    bench = commands.add_parser(
        "bench", help="estimator x controller benchmark grid over vehicles, seas and sensors",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=BENCH_DESCRIPTION)
    axes = bench.add_argument_group("the grid (each a space-separated list)")
    axes.add_argument("--vehicles", nargs="+", type=str,
                      help="usv hydrofoil rov dp hovercraft (default: all)")
    axes.add_argument("--estimators", nargs="+",
                      help=f"{' '.join(registry.names())}, or one registered with "
                           "estimators.registry.register (default: true raw kf akf ekf)")
    axes.add_argument("--controllers", nargs="+",
                      help="lqr, nominal, ppo/sac/td3/a2c (trained here per vehicle and "
                           "estimator) or sb3:DIR (a 'marine train' output) (default: lqr)")
    axes.add_argument("--seas", nargs="+", help="calm moderate rough (default: moderate)")
    axes.add_argument("--sensors", nargs="+",
                      help="default, or degradations kind=level joined by +: noise=K (K x the "
                           "default noise), quant=K (a step of K default stds), dropout=P, "
                           "delay=N (control periods); e.g. default noise=4 dropout=0.2")
    axes.add_argument("--seeds", type=int, help="episodes per cell, seeds 0..N-1 (default 5)")
    axes.add_argument("--seconds", type=float, help="episode length, s (default: the env's)")
    axes.add_argument("--timesteps", type=int,
                      help="training steps of each agent the grid trains (default 100000)")
    bench.add_argument("--quick", action="store_true",
                       help="a small grid over all five vehicles: true raw kf akf, lqr and ppo, "
                            "default and noise=32 sensors, 3 seeds of 60 s, 20000-step PPO "
                            "(other options override its settings)")
    bench.add_argument("--out", default="bench", metavar="DIR",
                       help="rows.csv, summary.md, figures, trained agents; a rerun resumes "
                            "(default: bench)")
    bench.add_argument("--backend", choices=("local", "ray"), default="local",
                       help="local processes (default) or Ray tasks")
    bench.add_argument("--address", help="Ray cluster address (auto, or HOST:PORT); without it "
                                         "--backend ray starts a local Ray")
    bench.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                       help="processes (local) or CPUs of the local Ray (default: all cores)")
    bench.add_argument("--json", metavar="PATH", help='also write {"rows": [...]} as JSON')
    bench.add_argument("--report", metavar="DIR",
                       help="also write DIR/index.html: the tables and figures in one page")
    bench.add_argument("--quiet", action="store_true", help="no progress bars")
    bench.set_defaults(run=_bench)

    envs = commands.add_parser("envs", help="list the environments with their spaces")
    envs.set_defaults(run=_envs)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except (ValueError, FileNotFoundError, ImportError) as error:
        print(f"marine {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
