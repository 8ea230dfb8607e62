"""``marine zoo``: list the trained agents shipped with the package, with how they were trained
and their measured cost ratio to LQR. Its arguments (:func:`arguments`) beside its handler
(:func:`handle`)."""

from __future__ import annotations

import argparse
from typing import Any

from . import common

#: The command's line in ``marine --help``.
HELP = "list the trained agents shipped with the package (zoo:...) and their cost / LQR's"
#: The command's description in its help (argparse fills the lines anew).
DESCRIPTION = """\
List the shipped agents by name (zoo:ROV-v0/residual_ppo), with their environment, kind,
estimator, training steps and wall time, and their mean cost over the LQR's behind the same
estimator on the tuning evaluation seeds (used to choose settings) and on held-out seeds (never
used for that); '-' where not measured. Evaluate one with 'marine evaluate NAME', load it with
agents.sb3.Agent.load("NAME"), re-train it with 'marine train --config
agents/zoo/ENV/KIND.yaml'.
"""
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "json": "also write {\"agents\": [{name, path, card...}]} as JSON",
    "force": "replace an existing --json",
}
#: The table's columns: heading and the card entry each shows.
_COLUMNS = ("agent", "env", "kind", "estimator", "steps", "time", "tuning", "held-out")


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine zoo``'s own arguments (none)."""


def handle(args: argparse.Namespace) -> int:
    """Run ``marine zoo`` as ``args`` ask; the exit code."""
    from ..sb3 import zoo

    out = common.output_file(args.json, args.force, "--json")
    found = zoo.entries()
    if not found:
        print(f"the zoo is empty: no trained agents are shipped (in {zoo.ZOO})")
    else:
        rows = [_row(entry.name, entry.card) for entry in found]
        widths = [max(len(text) for text in column) for column in zip(_COLUMNS, *rows,
                                                                       strict=True)]
        for line in (_COLUMNS, *rows):
            print("  ".join(text.ljust(width) for text, width in zip(line, widths,
                                                                      strict=True)).rstrip())
        print("cost / LQR's behind the same estimator (tuning and held-out seeds); evaluate one: "
              "marine evaluate NAME")
    common.write_json_output(out, {"agents": [{"name": entry.name, "path": str(entry.path),
                                               **entry.card} for entry in found]})
    return 0


def _row(name: str, card: dict[str, Any]) -> tuple[str, ...]:
    from ..sb3.zoo import format_duration

    scores = card.get("scores") or {}
    return (name, str(card["env_id"]).split("/")[-1], str(card["kind"]),
            str(card.get("estimator", "?")), str(card.get("timesteps", "?")),
            format_duration(float(card.get("wall_seconds") or 0.0)),
            _ratio(scores.get("tuning")), _ratio(scores.get("held_out")))


def _ratio(score: dict[str, Any] | None) -> str:
    """``0.93 (10 seeds)``, ``0.93 (10 seeds, 1 failed)``, or ``-`` when not measured."""
    if not score:
        return "-"
    failed = f", {score['failed']} failed" if score.get("failed") else ""
    return f"{score['cost_ratio']:.3g} ({len(score['seeds'])} seeds{failed})"
