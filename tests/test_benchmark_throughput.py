"""Smoke test of benchmarks/throughput.py: every case is timed against CartPole in the same
run, the table gives min/median/max and the issue's targets, the compile times are measured."""

import json
import sys

from benchmark_module import load_benchmark

bench = load_benchmark("throughput")


def test_ratios_per_repeat_and_targets_are_reported(tmp_path, monkeypatch, capsys):
    out = tmp_path / "rows.json"
    monkeypatch.setattr(sys, "argv", ["throughput.py", "--envs", "USV", "ROV", "--sizes", "4",
                                      "--steps", "40", "--repeats", "2", "--no-compile",
                                      "--json", str(out)])
    bench.main()
    table = capsys.readouterr().out
    assert "| USV | single | CartPole-v1 |" in table
    assert "| ROV | N=4 | CartPoleVectorEnv |" in table
    assert ">= 0.50" in table  # the ROV's single-env target
    rows = json.loads(out.read_text())["throughput"]
    assert [(r["vehicle"], r["case"]) for r in rows] == [("USV", "single"), ("ROV", "single"),
                                                       ("USV", 4), ("ROV", 4)]
    assert all(len(r["ratios"]) == 2 and min(r["ratios"]) > 0 for r in rows)


def test_targets_follow_the_issue():
    assert bench.target("Hydrofoil", "single") == 0.8 and bench.target("ROV", "single") == 0.5
    assert bench.target("USV", 1024) == 0.75 and bench.target("DPVessel", 1024) == 0.25
    assert bench.target("USV", 64) is None


def test_compile_times_are_read_from_fresh_processes():
    (row,) = bench.compile_times(["USV"])  # (that the second loads the first's: test_compiled)
    assert row["import_s"] > 0 and row["first_use_s"] > 0 and row["cached_s"] > 0
    assert "| USV |" in bench.format_compile([row])
