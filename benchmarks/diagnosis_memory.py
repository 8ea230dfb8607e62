"""Peak memory of ``marine diagnose`` against the length of the record.

Each record is made by ``marine simulate`` (the USV under its LQR autopilot, default sea and
sensors, streamed to Parquet in bounded memory) and diagnosed by ``marine diagnose`` in a
process of its own, whose peak resident memory (``ru_maxrss``) and CPU time (user + sys) come
from ``os.wait4``. A record longer than the seaway method's sample budget is cut to its most
excited part, and one sampled faster than the method's step is decimated first
(:mod:`estimators.diagnosis.sizing`): the table says what was judged. Acceptance (issue 57): a
2M-row record diagnosed, or cut with the reason printed, within 2 GB; an hour at 100 Hz (360k
rows) diagnosed.

    python benchmarks/diagnosis_memory.py [--rows 10000,50000,100000,360000@0.01,2000000]
                                          [--seed 1] [--records DIR] [--docs [PAGE]]

``ROWS@DT`` sets the environment's step (s; default the USV's 0.1).
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

from _common import add_docs_option, benchmark_run, check_page_path  # noqa: E402

TITLE = "Diagnosis: peak memory against the record's length"
ABOUT = __doc__.split("\n\n    python")[0].split("\n", 2)[2]
MARINE = [sys.executable, "-m", "agents.cli"]


def parse_rows(text: str) -> list[tuple[int, float | None]]:
    """``10000,360000@0.01`` -> ``[(10000, None), (360000, 0.01)]``."""
    out = []
    for item in text.split(","):
        rows, _, step = item.strip().partition("@")
        out.append((int(rows), float(step) if step else None))
    return out


def record(rows: int, step: float | None, seed: int, folder: Path) -> Path:
    """The USV record of ``rows`` samples at ``step`` s, made once and kept in ``folder``."""
    path = folder / f"usv_{rows}_{step or 0.1:g}s_seed{seed}.parquet"
    if not path.is_file():
        kwargs = [] if step is None else ["--env-kwargs", json.dumps({"dt": step})]
        subprocess.run([*MARINE, "simulate", "--env", "USV-v0", "--steps", str(rows),
                        "--seed", str(seed), "--policy", "lqr", "--out", str(path), "--quiet",
                        *kwargs], check=True, capture_output=True)
    return path


def measure(path: Path, folder: Path) -> dict[str, Any]:
    """Diagnose ``path`` in a process of its own: its peak RSS (GB), CPU time (s), exit code
    and the diagnosis' JSON (or its error line)."""
    out = folder / (path.stem + ".diagnosis.json")
    with tempfile.TemporaryFile("w+") as err:
        process = subprocess.Popen([*MARINE, "diagnose", str(path), "--quiet", "--force",
                                    "--json", str(out)], stdout=subprocess.DEVNULL,
                                   stderr=err)
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        err.seek(0)
        errors = [line for line in err.read().splitlines() if "error" in line]
    return {"peak_gb": usage.ru_maxrss / 1e6, "cpu_s": usage.ru_utime + usage.ru_stime,
            "exit": process.returncode, "error": errors[-1] if errors else "",
            "diagnosis": json.loads(out.read_text()) if process.returncode == 0 else None}


def judged(result: dict[str, Any]) -> str:
    """What the diagnosis judged, from its ``record``."""
    if result["diagnosis"] is None:
        return result["error"] or f"exit {result['exit']}"
    done = result["diagnosis"].get("record", {})
    parts = []
    if "decimated" in done:
        parts.append(f"decimated by {done['decimated']['factor']}")
    if "cut" in done:
        cut = done["cut"]
        parts.append(f"cut to {cut['samples']} ({cut['start']:.0f}-{cut['stop']:.0f} s)")
    return ", ".join(parts) or "whole"


def table(rows: Sequence[dict[str, Any]]) -> str:
    lines = ["| rows | step (s) | file (MB) | peak RSS (GB) | CPU (s) | judged | answer |",
             "|---:|---:|---:|---:|---:|---|---|"]
    for r in rows:
        answer = "error" if r["diagnosis"] is None else {
            True: "mismatch", False: "no mismatch", None: "cannot judge"}[
            r["diagnosis"]["mismatch"]]
        lines.append(f"| {r['rows']} | {r['step']:g} | {r['mb']:.1f} | {r['peak_gb']:.2f} | "
                     f"{r['cpu_s']:.0f} | {judged(r)} | {answer} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=parse_rows,
                        default=parse_rows("10000,50000,100000,360000@0.01,2000000"),
                        help="record lengths, ROWS or ROWS@STEP (s)")
    parser.add_argument("--seed", type=int, default=1, help="the simulations' seed")
    parser.add_argument("--records", type=Path, default=Path(tempfile.gettempdir())
                        / "marine_diagnosis_memory", help="where the records are kept")
    add_docs_option(parser, "diagnosis_memory")
    args = parser.parse_args(argv)
    check_page_path(parser, args.docs)
    args.records.mkdir(parents=True, exist_ok=True)
    results = []
    with benchmark_run("diagnosis_memory", sys.argv[1:] if argv is None else argv) as run:
        for rows, step in args.rows:
            path = record(rows, step, args.seed, args.records)
            result = {"rows": rows, "step": step or 0.1, "mb": path.stat().st_size / 1e6,
                      **measure(path, args.records)}
            results.append(result)
            print(f"{rows} rows: {result['peak_gb']:.2f} GB, {result['cpu_s']:.0f} s CPU, "
                  f"{judged(result)}", flush=True)
        run.show(table(results), heading="Peak memory of marine diagnose")
    if args.docs:
        run.write_page(args.docs, TITLE, ABOUT)
    return 0


if __name__ == "__main__":
    sys.exit(main())
