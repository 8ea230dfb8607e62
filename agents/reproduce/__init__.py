"""``marine reproduce NAME``: the source documents' experiments, re-run and compared.

Each entry is a module with ``reproduce(quick: bool = False, progress: bool = True) ->
Reproduction``. A reproduction runs the document's own settings and a corrected setting where the
document's are degenerate, averages over seeds and reports the spread.
"""

from __future__ import annotations

import importlib

from .base import Reproduction

#: name -> module defining ``reproduce``; imported on demand (some need optional extras).
REPRODUCTIONS: dict[str, str] = {
    "usv-quantized-observer": "agents.reproduce.usv_quantized_observer",
    "hydrofoil-akf": "agents.reproduce.hydrofoil_akf",
    "rov-online-id": "agents.reproduce.rov_online_id",
    "dp-wave-frequency": "agents.reproduce.dp_wave_frequency",
    "hovercraft-zigzag": "agents.reproduce.hovercraft_zigzag",
}


def run(name: str, quick: bool = False, progress: bool = True) -> Reproduction:
    """Run the reproduction ``name`` (one of :data:`REPRODUCTIONS`)."""
    if name not in REPRODUCTIONS:
        raise ValueError(f"unknown reproduction {name!r}; known: {', '.join(REPRODUCTIONS)}")
    return importlib.import_module(REPRODUCTIONS[name]).reproduce(quick=quick, progress=progress)


__all__ = ["REPRODUCTIONS", "Reproduction", "run"]
