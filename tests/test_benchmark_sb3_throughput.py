"""Smoke test of benchmarks/sb3_throughput.py: both backends train and step; the table prints."""

import json
import sys

from benchmark_module import load_benchmark

bench = load_benchmark("sb3_throughput")


def test_both_backends_are_measured_and_the_table_prints(tmp_path, monkeypatch, capsys):
    out = tmp_path / "rows.json"
    monkeypatch.setattr(sys, "argv", ["sb3_throughput.py", "--envs", "USV", "--timesteps", "512",
                                      "--n-envs", "2", "--repeats", "1", "--json", str(out)])
    bench.main()
    assert "| USV | PPO training | 2 | raw |" in capsys.readouterr().out
    rows = json.loads(out.read_text())["rows"]
    assert [r["what"] for r in rows] == ["PPO training", "env stepping"]
    assert all(r["native_steps_s"] > 0 and r["dummy_steps_s"] > 0 and r["ratio"] > 0
               for r in rows)
