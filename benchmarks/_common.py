"""What every benchmark script shares: one BLAS thread, and a results page with its provenance.

A benchmark runs inside :func:`benchmark_run`, which pins every BLAS (and OpenMP) library to one
thread with threadpoolctl, says so, and records the run (:func:`marine_envs.provenance.run_record`,
the wall time, the load average at its start and end). What the script shows with
:meth:`Run.show` is printed and kept, so ``--docs`` writes a page (:func:`write_page`) holding
exactly the text the script printed, its figures (saved by :meth:`Run.figure` with their
provenance in the PNG) and the record of the run::

    with benchmark_run("throughput", argv) as run:
        run.show(format_table(rows), heading="Steps per second against CartPole")
    if args.docs:
        run.write_page(args.docs, TITLE, ABOUT)
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shlex
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from marine_envs.files import WriteError, write_text
from marine_envs.provenance import run_record, save_figure

REPO = Path(__file__).resolve().parents[1]
#: where ``--docs`` writes ``<benchmark>.md`` unless told
RESULTS = REPO / "docs" / "results"


def pin_to_one_cpu() -> str:
    """Pin the process to the first CPU it may use (Linux); say what was done."""
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (no sched_setaffinity)"
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


def blas_threads() -> str:
    """The BLAS libraries loaded in this process and their threads, e.g. ``openblas 1``."""
    from threadpoolctl import threadpool_info

    pools = [p for p in threadpool_info() if p.get("user_api") == "blas"]
    return ", ".join(f"{p['internal_api']} {p['num_threads']}" for p in pools) or "none loaded"


@contextlib.contextmanager
def one_blas_thread() -> Iterator[str]:
    """Limit every BLAS and OpenMP library to one thread while the block runs; print and yield
    what was done. threadpoolctl limits the libraries already loaded, so numpy's and scipy's
    BLAS are loaded first."""
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401  (scipy carries a BLAS of its own)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        said = f"BLAS threads pinned to 1 (threadpoolctl): {blas_threads()}"
        print(said, flush=True)
        yield said


@dataclass(frozen=True)
class Block:
    """A table or text the benchmark printed, under a heading on its page."""

    heading: str
    text: str
    markdown: bool  # a Markdown table (rendered); otherwise shown verbatim


@dataclass
class Run:
    """A benchmark run: its record, and what it printed and drew, for its page."""

    name: str
    command: str
    record: dict[str, str]
    blas: str
    load_start: float
    changed: list[str] = field(default_factory=list)
    started: float = field(default_factory=time.perf_counter)
    blocks: list[Block] = field(default_factory=list)
    figures: list[tuple[Path, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    seconds: float | None = None
    load_end: float | None = None
    blas_end: str = ""

    def show(self, text: str, heading: str = "", *, markdown: bool = True) -> None:
        """Print ``text`` and keep it for the page (``markdown``: a Markdown table)."""
        print(text, flush=True)
        self.blocks.append(Block(heading, text, markdown))

    def note(self, text: str) -> None:
        """Print a remark and keep it for the page, after the description."""
        print(text, flush=True)
        self.notes.append(text)

    def figure(self, fig: Any, path: str | os.PathLike[str], caption: str,
               **savefig_options: Any) -> Path:
        """Save ``fig`` with the run's provenance in the PNG and show it on the page."""
        written = save_figure(fig, path, command=self.command, **savefig_options)
        print(f"wrote {written}", flush=True)
        self.figures.append((Path(written).resolve(), caption))
        return written

    def finish(self) -> None:
        """The wall time, the load and the BLAS threads at the end of the run."""
        self.seconds = time.perf_counter() - self.started
        self.load_end = _load()
        self.blas_end = blas_threads()

    def write_page(self, path: str | os.PathLike[str], title: str, about: str) -> Path:
        """Write this run's page (:func:`write_page`); exit with one line if it cannot."""
        try:
            return write_page(path, self, title, about)
        except WriteError as error:
            sys.exit(f"{self.name}: error: {error}")


def _load() -> float:
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


@contextlib.contextmanager
def benchmark_run(name: str, argv: Sequence[str]) -> Iterator[Run]:
    """Run the block with one BLAS thread and record it as ``python benchmarks/NAME.py ARGV``."""
    command = shlex.join(["python", f"benchmarks/{name}.py", *argv])
    with one_blas_thread() as pinned:
        run = Run(name, command, run_record(command), pinned, _load(), uncommitted_files())
        yield run
        run.finish()


def uncommitted_files() -> list[str]:
    """The checkout's tracked files that differ from its commit (what ``+dirty`` means in the
    record: often the outputs of other benchmarks, such as their pages and figures)."""
    try:
        status = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain",
                                 "--untracked-files=no"], capture_output=True, text=True,
                                timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return []
    return [line[3:] for line in status.stdout.splitlines()]


def add_docs_option(parser: argparse.ArgumentParser, name: str) -> None:
    """``--docs [PAGE]``: write the results page (default ``docs/results/NAME.md``)."""
    parser.add_argument("--docs", nargs="?", type=Path, const=RESULTS / f"{name}.md",
                        metavar="PAGE", help=f"write the results page (default: "
                        f"docs/results/{name}.md)")


def chosen_names(parser: argparse.ArgumentParser, text: str, known: Sequence[str],
                 what: str) -> list[str]:
    """The comma-separated names in ``text`` (an option's value), each one of ``known``; an
    unknown or empty choice is the parser's error (one line, exit 2), naming the known ones."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = sorted(set(names) - set(known))
    if unknown or not names:
        parser.error(f"unknown {what}(s) {unknown or '(none)'}; choose from {', '.join(known)}")
    return names


def check_page_path(parser: argparse.ArgumentParser, page: Path | None) -> None:
    """Refuse a page that cannot be written before the run, not after it."""
    if page is None:
        return
    folder = page.parent if str(page.parent) else Path(".")
    if page.is_dir() or not folder.is_dir() or not os.access(folder, os.W_OK):
        parser.error(f"--docs {page}: cannot write there (not a writable folder)")


def write_page(path: str | os.PathLike[str], run: Run, title: str, about: str) -> Path:
    """Write the results page of ``run`` to ``path`` atomically: the title, ``about`` (what is
    measured and how), the run's notes, every block it printed (verbatim), its figures and the
    record of the run (command, code, date, machine, BLAS threads, wall time, load).

    :raises marine_envs.files.WriteError: when the page cannot be written (names it).
    """
    path = Path(path)
    parts = [f"# {title}", "", about.strip(), ""]
    parts += [line for note in run.notes for line in (note, "")]
    for block in run.blocks:
        if block.heading:
            parts += [f"## {block.heading}", ""]
        parts += [block.text if block.markdown else f"```text\n{block.text}\n```", ""]
    for figure, caption in run.figures:
        relative = os.path.relpath(figure, path.resolve().parent)
        parts += [f"![{caption}]({Path(relative).as_posix()})", "", f"*{caption}*", ""]
    parts += ["## How this page was made", "", *provenance_lines(run), ""]
    write_text(path, "\n".join(parts))
    print(f"wrote {path}", flush=True)
    return path


def provenance_lines(run: Run) -> list[str]:
    """The record of ``run`` as a Markdown list."""
    record, cores = run.record, os.cpu_count() or 1
    load = f"{run.load_start:.1f} at the start"
    if run.load_end is not None:
        load += f", {run.load_end:.1f} at the end"
    busiest = max(run.load_start, run.load_end or 0.0)
    load += f" (1-minute average, {cores} cores)"
    if busiest > cores:
        load += ": other jobs shared the machine, so absolute rates are lower than on an idle " \
                "one; ratios are to references measured in the same run"
    blas = run.blas + (f"; at the end: {run.blas_end}" if run.blas_end else "")
    wall = "" if run.seconds is None else f"{run.seconds:.0f} s"
    return [f"- command: `{run.command}`",
            f"- code: marine-envs {record['version']}, commit `{record['commit']}`"
            + (f" (uncommitted changes: {', '.join(run.changed)})" if run.changed else ""),
            f"- date: {record['date']}",
            f"- machine: {record['machine']}",
            f"- {blas}",
            f"- wall time: {wall}",
            f"- load average: {load}"]
