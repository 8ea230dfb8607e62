"""The benchmarks' results pages (benchmarks/_common.py): the page holds exactly what the script
printed, its figure with provenance and the record of the run; an unwritable page is refused
cleanly; BLAS runs on one thread inside a benchmark run."""

import argparse
import sys

import numpy as np
import pytest
from benchmark_module import BENCHMARKS, load_benchmark
from threadpoolctl import threadpool_info

from marine_envs.files import WriteError
from marine_envs.provenance import read_figure_provenance

sys.path.insert(0, str(BENCHMARKS))
import _common  # noqa: E402


def _blas_threads() -> list[int]:
    return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]


def _table(rng: np.random.Generator) -> str:
    rows = [f"| case {k} | {value:.4f} |" for k, value in enumerate(rng.uniform(0, 10, 4))]
    return "\n".join(["| case | ratio |", "| --- | ---: |", *rows])


def test_the_page_holds_the_printed_tables_the_figure_and_the_record(tmp_path, capsys):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = _table(np.random.default_rng(3))
    checks = "pass  a check   max|dx| 1.0e-12\nFAIL  another   2 of 3"
    with _common.benchmark_run("demo", ["--quick", "--docs"]) as run:
        run.note("A remark on this run.")
        run.show(table, "Ratios")
        run.show(checks, "Checks", markdown=False)
        fig, ax = plt.subplots()
        ax.plot([0, 1], [1, 0])
        (tmp_path / "figures").mkdir()
        run.figure(fig, tmp_path / "figures" / "demo.png", "A line", dpi=50)
        plt.close(fig)
    printed = capsys.readouterr().out
    assert table in printed and checks in printed
    assert "BLAS threads pinned to 1 (threadpoolctl)" in printed

    page = run.write_page(tmp_path / "demo.md", "Demo", "What is measured, and how.")
    text = page.read_text()
    assert text.startswith("# Demo\n\nWhat is measured, and how.\n\nA remark on this run.\n")
    assert f"## Ratios\n\n{table}\n" in text  # verbatim: the same text the script printed
    assert f"## Checks\n\n```text\n{checks}\n```\n" in text
    assert "![A line](figures/demo.png)" in text
    record = run.record
    for line in ("- command: `python benchmarks/demo.py --quick --docs`",
                 f"- code: marine-envs {record['version']}, commit `{record['commit']}`",
                 f"- date: {record['date']}", f"- machine: {record['machine']}",
                 "- BLAS threads pinned to 1 (threadpoolctl)", "- wall time: ",
                 "- load average: "):
        assert line in text
    assert f"{run.load_start:.1f} at the start, {run.load_end:.1f} at the end" in text
    provenance = read_figure_provenance(tmp_path / "figures" / "demo.png")
    assert provenance["command"] == "python benchmarks/demo.py --quick --docs"
    assert provenance["commit"] == record["commit"]


def test_an_unwritable_page_is_refused_naming_it_and_nothing_is_left(tmp_path):
    with _common.benchmark_run("demo", []) as run:
        run.show("| a |\n| --- |\n| 1 |")
    folder = tmp_path / "missing"
    with pytest.raises(WriteError, match=f"cannot write {folder / 'demo.md'}"):
        _common.write_page(folder / "demo.md", run, "Demo", "About.")
    with pytest.raises(SystemExit, match=r"^demo: error: cannot write .*demo\.md"):
        run.write_page(folder / "demo.md", "Demo", "About.")
    assert not folder.exists() and list(tmp_path.iterdir()) == []

    parser = argparse.ArgumentParser(prog="demo.py")
    _common.add_docs_option(parser, "demo")
    assert parser.parse_args(["--docs"]).docs == _common.RESULTS / "demo.md"
    with pytest.raises(SystemExit) as exit_:  # refused before the run, not after it
        _common.check_page_path(parser, parser.parse_args(["--docs", str(folder / "x.md")]).docs)
    assert exit_.value.code == 2


def test_a_failed_write_keeps_the_earlier_page(tmp_path, monkeypatch):
    page = tmp_path / "demo.md"
    page.write_text("the earlier page\n")
    with _common.benchmark_run("demo", []) as run:
        run.show("| a |\n| --- |\n| 1 |")

    def full_disk(self, text, encoding=None):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(type(page), "write_text", full_disk)
    with pytest.raises(WriteError, match="No space left on device"):
        _common.write_page(page, run, "Demo", "About.")
    monkeypatch.undo()
    assert page.read_text() == "the earlier page\n"
    assert [p.name for p in tmp_path.iterdir()] == ["demo.md"]


def test_blas_runs_on_one_thread_inside_a_benchmark_and_is_restored_after(tmp_path,
                                                                         monkeypatch, capsys):
    bench = load_benchmark("throughput")
    seen = []
    measure = bench.measure

    def measure_and_look(*args, **kwargs):
        seen.append(_blas_threads())
        return measure(*args, **kwargs)

    monkeypatch.setattr(bench, "measure", measure_and_look)
    before = _blas_threads()
    page = tmp_path / "throughput.md"
    bench.main(["--envs", "USV", "--sizes", "4", "--steps", "40", "--repeats", "1",
                "--no-compile", "--docs", str(page)])
    assert seen and seen[0] and all(n == 1 for n in seen[0])
    assert _blas_threads() == before
    printed = capsys.readouterr().out
    tables = _tables(printed[printed.index("| vehicle | case |"):])
    assert "| USV | N=4 | CartPoleVectorEnv |" in tables[0]
    assert all(table in page.read_text() for table in tables)  # each printed table on the page


def _tables(text: str) -> list[str]:
    """The markdown tables of ``text``: runs of consecutive lines that start with ``|``."""
    tables, rows = [], []
    for line in [*text.splitlines(), ""]:
        if line.startswith("|"):
            rows.append(line)
        elif rows:
            tables.append("\n".join(rows))
            rows = []
    return tables


def test_the_results_index_lists_every_page_with_its_command_and_time(tmp_path):
    with _common.benchmark_run("throughput", ["--docs"]) as run:
        run.show("| a |\n| --- |\n| 1 |")
    run.write_page(tmp_path / "throughput.md", "Environment throughput",
                   "Steps per second against CartPole (`CartPole-v1`: 1.5 x). More words.\n"
                   "A line.")
    (tmp_path / "index.md").write_text("an older index\n")
    index = load_benchmark("results_index")
    assert index.main(["--out", str(tmp_path / "index.md")]) == 0
    text = (tmp_path / "index.md").read_text()
    row = next(line for line in text.splitlines() if line.startswith("| [Environment"))
    assert row.startswith("| [Environment throughput](throughput.md) | Steps per second "
                          "against CartPole (`CartPole-v1`: 1.5 x). | "
                          "`python benchmarks/throughput.py --docs` | ")
    assert f"| {run.seconds:.0f} s | {run.record['date'][:10]} | {run.load_start:.1f} |" in row
    assert "```{toctree}\n:hidden:\n\nthroughput\n```" in text
    assert "`python benchmarks/filters.py --docs`" in text  # no page yet: named
    assert "`python benchmarks/throughput.py --docs`." not in text
