"""Smoke test of benchmarks/throughput.py: every case is timed against CartPole in the same
run, the table gives min/median/max and the issue's targets, the regimes of issue 59 are paired
with their references, the compile times are measured."""

import json
import sys

from benchmark_module import load_benchmark

bench = load_benchmark("throughput")


def test_ratios_per_repeat_and_targets_are_reported(tmp_path, monkeypatch, capsys):
    out = tmp_path / "rows.json"
    monkeypatch.setattr(sys, "argv", ["throughput.py", "--envs", "USV", "ROV", "--sizes", "4",
                                      "--steps", "40", "--repeats", "2", "--no-compile",
                                      "--no-regimes", "--json", str(out)])
    bench.main()
    table = capsys.readouterr().out
    assert "| USV | single | CartPole-v1 |" in table
    assert "| ROV | N=4 | CartPoleVectorEnv |" in table
    assert ">= 0.50" in table  # the ROV's single-env target
    rows = json.loads(out.read_text())["throughput"]
    assert [(r["vehicle"], r["case"]) for r in rows] == [("USV", "single"), ("ROV", "single"),
                                                       ("USV", 4), ("ROV", 4)]
    assert all(len(r["ratios"]) == 2 and min(r["ratios"]) > 0 for r in rows)


def test_regimes_are_paired_with_their_references(tmp_path, monkeypatch, capsys):
    out = tmp_path / "rows.json"
    monkeypatch.setattr(sys, "argv", ["throughput.py", "--envs", "USV", "--sizes", "4",
                                      "--steps", "20", "--repeats", "2", "--no-compile",
                                      "--regime-size", "4", "--json", str(out)])
    bench.main()
    table = capsys.readouterr().out
    rows = json.loads(out.read_text())["regimes"]
    assert [(r["case"], r["reference"]) for r in rows] == [
        ("Hydrofoil, zero action", "CartPole-v1"), ("USV diagnosed", "USV"),
        ("Hydrofoil, zero action, N=4", "CartPoleVectorEnv"),
        ("Hydrofoil, zero action, same-step restarts, N=4", "CartPoleVectorEnv"),
        ("USV, N=4", "CartPoleVectorEnv"), ("USV, BLAS default threads, N=4", "USV, N=4"),
        ("USV diagnosed, N=4", "USV, N=4")]
    assert all(len(r["ratios"]) == 2 and min(r["ratios"]) > 0 for r in rows)
    assert [r["target"] for r in rows[:4]] == [0.5, 2 / 3, 0.1, 0.1]
    assert "| Hydrofoil, zero action | CartPole-v1 |" in table and ">= 0.67" in table
    assert "| USV, BLAS default threads (" in table


def test_zero_action_broaches_the_hydrofoil_within_a_few_dozen_steps():
    # the regime the zero-action rows time: resets every few dozen steps, not at the end
    run = bench.single_stepper(bench.SHORT["Hydrofoil"], bench._zero_action)
    env = bench.gym.make(bench.SHORT["Hydrofoil"])
    env.reset(seed=0)
    zero = bench._zero_action(env)
    lengths, steps = [], 0
    while len(lengths) < 5:
        _, _, terminated, truncated, _ = env.step(zero)
        steps += 1
        if terminated or truncated:
            lengths.append(steps)
            steps = 0
            env.reset()
    assert max(lengths) < 100 and run(10) > 0


def test_targets_follow_the_issue():
    assert bench.target("Hydrofoil", "single") == 0.8 and bench.target("ROV", "single") == 0.5
    assert bench.target("USV", 1024) == 0.75 and bench.target("DPVessel", 1024) == 0.25
    assert bench.target("USV", 64) is None


def test_compile_times_are_read_from_fresh_processes():
    (row,) = bench.compile_times(["USV"])  # (that the second loads the first's: test_compiled)
    assert row["import_s"] > 0 and row["first_use_s"] > 0 and row["cached_s"] > 0
    assert "| USV |" in bench.format_compile([row])
