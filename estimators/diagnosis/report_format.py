"""What both reports share: a headless pyplot, saving a figure, numbers and text in Markdown."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np


def pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig: Any, path: Path) -> None:
    """Save ``fig`` (whole or not at all, its provenance inside) and free it."""
    from marine_envs.provenance import save_figure

    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    fig.clf()
    import matplotlib.pyplot as plt

    plt.close(fig)


def num(value: Any) -> str:
    return f"{value:.4g}" if isinstance(value, float | np.floating) else str(value)


def cell(text: str) -> str:
    """Text safe inside a Markdown table cell (pipes escaped, no line breaks)."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text)


def parameters(finding: Any) -> str:
    """A finding's parameters, each with its standard deviation where it has one."""
    items = []
    for name, value in finding.parameters.items():
        std = finding.std.get(name)
        items.append(f"{name} = {num(value)}" + (f" ± {num(std)}" if std is not None else ""))
    return ", ".join(items)


def change(before: float, after: float) -> str:
    """The relative change from ``before`` to ``after``, e.g. ``-54%``."""
    return f"{(after - before) / before:+.0%}" if before > 0 else "–"
