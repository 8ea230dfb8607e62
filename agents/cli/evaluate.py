"""``marine evaluate``: score an agent ``marine train`` saved on seeded episodes. Its arguments
(:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse

from . import common

#: The command's line in ``marine --help``.
HELP = ("evaluate an agent 'marine train' saved (or a shipped one, zoo:...): cost and "
        "errors over seeded episodes")
#: The command's description in its help (argparse fills the lines anew).
DESCRIPTION = """\
Run the agent over seeded episodes behind its training estimator and print the task's quadratic
cost, failures, RMS errors of the weighted states and inputs (angles in degrees), the fraction of
saturated steps and the estimator's RMS errors, as mean ± std over the episodes.
"""
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "seed": "first episode's seed; the others follow (default 0)",
    "json": "also write {\"rows\": [...]} as JSON",
    "force": "replace an existing --json",
    "quiet": None,
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine evaluate``'s own arguments."""
    parser.add_argument("dir", help="the directory 'marine train --out' wrote (its model.zip, "
                                    "else its latest checkpoint), a model file in it "
                                    "(e.g. checkpoints/model_8192_steps.zip), or a shipped "
                                    "agent's name (e.g. zoo:ROV-v0/residual_ppo: 'marine zoo' "
                                    "lists them)")
    parser.add_argument("--episodes", type=common.positive_int, default=5,
                        help="episodes (default 5)")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine evaluate`` as ``args`` ask; the exit code."""
    import numpy as np

    from .. import sb3
    from ..evaluation import episode_steps

    seed = 0 if args.seed is None else args.seed  # --seed's default here
    out = common.output_file(args.json, args.force, "--json")
    # a run folder, a checkpoint, a model file or a zoo name
    saved = sb3.find_agent(sb3.agent_path(args.dir))
    config = sb3.read_config(saved.run)
    steps = episode_steps(config["env_id"], config.get("max_episode_steps"))
    named = f"{args.dir} " if sb3.is_zoo_name(args.dir) else ""
    print(f"{named}{saved.model}" + (f" ({saved.timesteps} steps)" if saved.timesteps else "")
          + f": {config['env_id']} behind {config.get('estimator') or 'raw'}")
    with common.progress_bar(steps, "evaluating", not args.quiet) as bar:
        rows = sb3.evaluate(saved.model, args.episodes, seed,
                            progress=None if bar is None else bar.update)
        if bar is not None:
            bar.total = bar.n  # all boats done: the episodes may have ended early
    print(f"{args.episodes} episodes, seeds {seed}..{seed + args.episodes - 1} "
          "(mean ± std; angles in degrees):")
    for key in rows[0]:
        if key != "seed":
            values = [row[key] for row in rows]
            print(f"  {key:28s} {np.mean(values):12.5g} ± {np.std(values):.3g}")
    common.write_json_output(out, {"rows": rows})
    return 0
