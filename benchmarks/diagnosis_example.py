"""The README's diagnosis example, run end to end: a USV recording with a hidden rudder delay,
diagnosed as ``marine diagnose delay.csv --report delay_report`` does, and the report's figure of
the held-out prediction errors before and after the finding.

The recording is ``synthesize("usv", [typical_effect("usv", "input_delay", "delta")],
noise=0.1, seed=1)`` (the truth: a 0.6 s delay), written as CSV and read back as the command
line reads it. The figure is written to ``docs/diagnosis/usv_input_delay.png`` with this run's
provenance in the PNG.

    python benchmarks/diagnosis_example.py [--figure PATH] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import tempfile  # noqa: E402
from collections.abc import Iterator, Sequence  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402
from unittest import mock  # noqa: E402

from _common import REPO, Run, add_docs_option, benchmark_run, check_page_path  # noqa: E402

from estimators.diagnosis import diagnose, report, synthesize, typical_effect  # noqa: E402
from marine_envs.recording import read_recording, write_recording  # noqa: E402

FIGURE = REPO / "docs" / "diagnosis" / "usv_input_delay.png"
CAPTION = ("3 s-ahead prediction error of each channel against its start time; right of the "
           "black line: held out, before (blue) and after (orange) the finding")
TITLE = "Diagnosis example: a rudder delay"
ABOUT = """\
The diagnosis of the README's example end to end: a closed-loop USV recording with a hidden
0.6 s rudder delay (`synthesize("usv", [typical_effect("usv", "input_delay", "delta")],
noise=0.1, seed=1)`), written as CSV and read back, diagnosed against the nominal model as
`marine diagnose delay.csv --report delay_report` does. The text is the diagnosis's summary; the
figure is the report's `prediction_errors.png`: each channel's 3 s-ahead prediction error
before (blue) and after (orange) the finding, on the held-out last 30 % of the record."""


@contextmanager
def figures_with_provenance(bench: Run) -> Iterator[None]:
    """The report's figure saved through :meth:`Run.figure` (with this run's provenance) rather
    than the report's own plain ``save``."""
    import matplotlib.pyplot as plt

    def save(fig: Any, path: Path) -> None:
        fig.tight_layout()
        bench.figure(fig, path, CAPTION, dpi=100)
        plt.close(fig)

    with mock.patch.object(report, "save", save):
        yield


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--figure", type=Path, default=FIGURE,
                        help="where the figure goes (default docs/diagnosis/usv_input_delay.png)")
    add_docs_option(parser, "diagnosis_example")
    args = parser.parse_args(argv)
    check_page_path(parser, args.docs)
    with benchmark_run("diagnosis_example", argv) as bench:
        effect = typical_effect("usv", "input_delay", "delta")
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "delay.csv"
            write_recording(synthesize("usv", [effect], noise=0.1, seed=1), path)
            recording = read_recording(path)
        diagnosis = diagnose(recording, recording.model)
        bench.show(diagnosis.summary(), "The diagnosis", markdown=False)
        with figures_with_provenance(bench):
            report.plot_prediction_errors(diagnosis, args.figure)
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)
    return 0 if diagnosis.findings else 1


if __name__ == "__main__":
    sys.exit(main())
