"""Smoke test of benchmarks/sb3_throughput.py: both backends train and step; the table prints."""

import importlib.util
import json
import sys
from pathlib import Path

PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "sb3_throughput.py"
spec = importlib.util.spec_from_file_location("benchmark_sb3", PATH)
bench = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = bench
spec.loader.exec_module(bench)


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
