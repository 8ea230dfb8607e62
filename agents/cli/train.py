"""``marine train``: train a Stable-Baselines3 agent on the batched environment (or continue one,
``--resume``). Its arguments (:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from . import common

#: ``marine train``'s algorithms and backends: agents.sb3's ALGOS and BACKENDS, named here so
#: that the parser (``--help``, ``--version``, any command) does not import torch.
TRAIN_ALGOS = ("ppo", "sac", "td3", "a2c", "ppo_lstm")
TRAIN_BACKENDS = ("native", "dummy")

#: ``marine train`` options that --resume takes from the run's config.json instead.
RESUME_TAKES = ("env_id", "algo", "estimator", "n_envs", "backend", "seed", "out", "config",
                "residual", "residual_scale")


#: The command's line in ``marine --help``.
HELP = "train a Stable-Baselines3 agent (PPO, SAC, TD3, A2C) on an environment"
#: The command's description in its help (argparse fills the lines anew).
DESCRIPTION = """\
Train an SB3 agent on the native batched environment, optionally behind a state estimator.
Hyperparameters per vehicle and algorithm come from agents/hyperparams.yaml (RL-Zoo style; --config
another file); writes config.json (at once, then final), model.zip, vecnormalize.pkl (if
normalised) and checkpoints/ into --out. Where the settings give validation_episodes, model.zip is
the checkpoint that did best on them (fewest failures, then least cost) and last_model.zip the
last. Ctrl-C stops at the next step, saves as at the end and exits with code 130; --resume DIR
continues from the last saved agent with its step count.
"""
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "seed": "seed (default 0)",
    "force": "replace a run already in --out (its model, checkpoints, logs)",
    "quiet": None,
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine train``'s own arguments."""
    from estimators import registry

    parser.add_argument("env_id", nargs="?", type=common.env_id,
                        help="environment id, e.g. marine_envs/USV-v0 (or USV-v0)")
    parser.add_argument("--algo", choices=TRAIN_ALGOS,
                        help="ppo, sac, td3, a2c or ppo_lstm (sb3-contrib's RecurrentPPO: the "
                             "recurrent extra); default ppo")
    parser.add_argument("--estimator", choices=registry.names(), metavar="ESTIMATOR",
                        help="what the agent sees: raw (the sensors, the default), true (the "
                             f"true state) or an estimator: {registry.describe()}")
    parser.add_argument("--timesteps", type=common.positive_int,
                        help="environment steps (default: the YAML's n_timesteps; with "
                             "--resume: the total to reach, default the run's own)")
    parser.add_argument("--n-envs", type=common.positive_int,
                        help="boats stepped together (default: the YAML's)")
    parser.add_argument("--backend", choices=TRAIN_BACKENDS,
                        help="native (our batched env, the default) or dummy (SB3's "
                             "DummyVecEnv)")
    parser.add_argument("--residual", choices=("lqr",),
                        help="learn a correction to this controller on the same estimate "
                             "(residual RL): the action is the LQR's plus the agent's, bounded "
                             "by --residual-scale; the untrained agent is the LQR, and a "
                             "correction is kept only where validation scores it better")
    parser.add_argument("--residual-scale", type=float, metavar="FRACTION",
                        help="bound of the correction, a fraction of each action's half range "
                             "(default 0.5; with --residual)")
    parser.add_argument("--out", metavar="DIR", help="output directory")
    parser.add_argument("--resume", metavar="DIR",
                        help="continue the run in DIR (a 'marine train --out' folder) from its "
                             "last saved agent, with its config.json's settings")
    parser.add_argument("--config", metavar="YAML",
                        help="hyperparameters file in agents/hyperparams.yaml's format; its "
                             "agent: section, if any, gives the environment id, --algo, "
                             "--estimator, --seed and --out where not given (a zoo agent's "
                             "re-train file, e.g. agents/zoo/ROV-v0/residual_ppo.yaml)")
    parser.set_defaults(run=lambda args: handle(args, parser))


def handle(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """Run ``marine train`` as ``args`` ask (``parser`` reports a
    misuse of its options); the exit code."""
    from .. import sb3

    if args.resume is not None:
        given = [name for name in RESUME_TAKES if getattr(args, name) is not None]
        if given:
            parser.error(f"--resume takes the run's settings from {args.resume}/config.json: "
                         f"drop {', '.join(_option(n) for n in given)}")
        # refuses a live run, then finds the last agent that loads, before any work
        result = sb3.resume(Path(args.resume), args.timesteps, progress_bar=not args.quiet)
    else:
        config = Path(args.config) if args.config else sb3.HYPERPARAMS
        if not config.is_file():
            raise FileNotFoundError(f"--config {config}: no such file")
        run = _from_config(args, sb3.agent_section(config) if args.config else {})
        if run["env_id"] is None or run["out"] is None:
            parser.error("the environment id and --out DIR are required (or --resume DIR, or "
                         "--config YAML whose agent: section gives them)")
        common.check_estimator(run["estimator"])
        if args.residual_scale is not None and args.residual is None:
            parser.error("--residual-scale needs --residual")
        overrides = {key: value for key, value in (("residual", args.residual),
                                                   ("residual_scale", args.residual_scale))
                     if value is not None}
        sb3.settings(run["env_id"], run["algo"], run["estimator"], args.timesteps, run["seed"],
                     args.n_envs, run["backend"], overrides,
                     max_episode_steps=run["max_episode_steps"],
                     hyperparams_file=config)
        sb3.check_not_in_use(Path(run["out"]))  # a live run is named as such, --force or not
        out = common.output_dir(run["out"], args.force, "--out", sb3.existing_run,
                                " (a training run: --resume it)")
        result = sb3.train(run["env_id"], run["algo"], run["estimator"], args.timesteps,
                           out, run["seed"], args.n_envs, run["backend"],
                           progress_bar=not args.quiet, hyperparams=overrides,
                           max_episode_steps=run["max_episode_steps"], hyperparams_file=config,
                           force=args.force)
    if result.stop_signal is not None:
        print(f"marine train: interrupted at {result.timesteps} steps, saved to {result.out} "
              f"(continue: marine train --resume {result.out})", file=sys.stderr)
        return 128 + result.stop_signal  # the shell's convention: 130 SIGINT, 143 SIGTERM
    since = f" (from {result.resumed_from})" if result.resumed_from else ""
    print(f"trained {result.timesteps} steps{since} in {result.wall_seconds:.1f} s "
          f"({result.steps_per_second:.0f} steps/s); saved to {result.out}")
    if result.selected is not None:
        best = result.selected
        print(f"model.zip is the agent of {best['timesteps']} steps, the best on validation "
              f"({best['failed']} failed, mean cost {best['cost']:.4g}); the last is "
              "last_model.zip")
        if best["timesteps"] == 0:
            print("no correction scored better than the controller it corrects: the agent "
                  "is that controller (it learnt nothing to keep)")
    return 0


def _from_config(args: argparse.Namespace, section: dict[str, Any]) -> dict[str, Any]:
    """The run's settings: those given on the command line, else the config file's ``agent:``
    section's (a zoo agent's re-train file), else the defaults."""
    defaults = {"env_id": None, "algo": "ppo", "estimator": None, "seed": 0, "out": None,
                "backend": "native", "max_episode_steps": None}
    given = {key: getattr(args, key, None) for key in defaults}
    return {key: given[key] if given[key] is not None else section.get(key, default)
            for key, default in defaults.items()}


def _option(dest: str) -> str:
    return "the environment id" if dest == "env_id" else "--" + dest.replace("_", "-")
