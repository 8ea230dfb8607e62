"""What a reproduction returns: numbers for JSON, a text table for people, and its figure."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np


@dataclasses.dataclass
class Reproduction:
    """The outcome of one ``marine reproduce`` run.

    :param name: the reproduction's name.
    :param summary: JSON-serialisable results (the keys the issue names, plus ``spread`` data).
    :param text: a human-readable table, with which setting is the document's and which the
        corrected one, and why.
    :param plot: draws the figure(s) into the given PNG path.
    """

    name: str
    summary: dict[str, Any]
    text: str
    plot: Callable[[Path], None]


def spread(values: Sequence[float]) -> dict[str, float | list[float]]:
    """Mean, standard deviation, min and max of per-seed values, and the values themselves."""
    v = np.asarray(values, dtype=float)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
            "min": float(v.min()), "max": float(v.max()), "per_seed": v.tolist()}
