"""Helpers shared by the benchmark scripts."""

from __future__ import annotations

import os


def pin_to_one_cpu() -> str:
    """Pin the process to the first CPU it may use (Linux); say what was done."""
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (no sched_setaffinity)"
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"
