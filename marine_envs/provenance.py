"""Where a figure or a result came from: the command, the code, the machine and the date.

Every figure the project writes carries this record in its PNG text chunks (read it back with
:func:`read_figure_provenance`), and every results page in the documentation prints it, so a
number or a plot can always be traced to the run that made it.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

from marine_envs.files import atomic_path

__all__ = ["run_record", "machine_description", "save_figure", "read_figure_provenance"]

_ROOT = Path(__file__).resolve().parents[1]


def machine_description() -> str:
    """One line naming the processor, cores, memory, Python and the BLAS threads in use."""
    cpu = _cpu_model()
    memory = _memory_gib()
    parts = [cpu, f"{os.cpu_count()} cores"]
    if memory:
        parts.append(f"{memory:.0f} GiB")
    parts.append(f"Python {platform.python_version()}")
    blas = _blas_threads()
    if blas:
        parts.append(blas)
    return ", ".join(parts)


def run_record(command: str | None = None) -> dict[str, str]:
    """The provenance of the current run.

    :param command: the command line to record; by default this process's own arguments.
    :return: ``command``, ``version`` (the package's), ``commit`` (the git commit of the
        checkout, ``+dirty`` when its code or data has uncommitted changes, ``unknown``
        outside a checkout),
        ``date`` (UTC, ISO 8601), ``machine`` (:func:`machine_description`) and ``load``
        (the 1-minute load average when the run started its record).
    """
    from marine_envs import __version__

    if command is None:
        command = " ".join(shlex.quote(a) for a in [Path(sys.argv[0]).name, *sys.argv[1:]])
    load = f"{os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else "unknown"
    return {
        "command": command,
        "version": __version__,
        "commit": _git_commit(),
        "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "machine": machine_description(),
        "load": load,
    }


def save_figure(fig: Any, path: str | os.PathLike[str], *, command: str | None = None,
                **savefig_options: Any) -> Path:
    """Save a matplotlib figure atomically, its provenance in the PNG's text chunks.

    :param fig: a ``matplotlib.figure.Figure``.
    :param path: the file; its suffix chooses the format (PNG gets the provenance).
    :param command: the command to record (default: this process's arguments).
    :param savefig_options: passed to ``Figure.savefig`` (``dpi``, ``bbox_inches``, ...).
    :return: the path written.
    :raises marine_envs.files.WriteError: when the file cannot be written (names it).
    """
    target = Path(path)
    if target.suffix.lower() == ".png":
        record = run_record(command)
        savefig_options.setdefault("metadata", {}).update(
            {"Software": f"marine-envs {record['version']}",
             "Source": record["command"],
             "Comment": "; ".join(f"{k}={v}" for k, v in record.items())})
    with atomic_path(target) as temporary:
        fig.savefig(temporary, format=target.suffix.lstrip(".") or None, **savefig_options)
    return target


def read_figure_provenance(path: str | os.PathLike[str]) -> dict[str, str]:
    """The provenance a PNG written by :func:`save_figure` carries ({} when it has none)."""
    from PIL import Image  # matplotlib's own dependency

    with Image.open(path) as image:
        comment = image.info.get("Comment", "")
    record: dict[str, str] = {}
    for part in comment.split("; "):
        key, sep, value = part.partition("=")
        if sep:
            record[key] = value
    return record


def _cpu_model() -> str:
    with contextlib.suppress(OSError):  # not Linux: the platform's own word
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def _memory_gib() -> float | None:
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None
    return pages * size / 2**30


def _blas_threads() -> str:
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return ""
    pools = [p for p in threadpool_info() if p.get("user_api") == "blas"]
    return ", ".join(f"{p['internal_api']} {p['num_threads']} thread(s)" for p in pools)


def _git_commit() -> str:
    try:
        head = subprocess.run(["git", "-C", str(_ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=10, check=True)
        # changed code or data; the figures and results pages runs rewrite do not count
        dirty = subprocess.run(["git", "-C", str(_ROOT), "status", "--porcelain",
                                "--untracked-files=no", "--", ".", ":(exclude)*.png",
                                ":(exclude)docs/results"],
                               capture_output=True, text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
