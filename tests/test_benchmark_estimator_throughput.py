"""Smoke test of benchmarks/estimator_throughput.py: checks pass on small sizes, table prints."""

import importlib.util
import sys
from pathlib import Path

import pytest

pytest.importorskip("filterpy")

PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "estimator_throughput.py"
# loaded under another name: "estimators" is the package the benchmark measures
spec = importlib.util.spec_from_file_location("benchmark_estimators", PATH)
bench = importlib.util.module_from_spec(spec)
sys.modules[spec.name] = bench  # dataclasses look their module up
spec.loader.exec_module(bench)


def test_checks_pass_on_small_sizes():
    system = bench.random_system()
    checks = [bench.batch_vs_single(system, adaptive=False, batch=64, steps=40, rows=4),
              bench.batch_vs_single(system, adaptive=True, batch=64, steps=40, rows=4),
              bench.ours_vs_filterpy(system, steps=50),
              bench.float32_batch(50, 50),
              bench.float32_sequential(300, chunk=128)]
    assert all(c["passed"] for c in checks), bench.format_checks(checks)


def test_table_has_every_row():
    cases = bench.build_cases(bench.random_system(), 5, 2, bench.np.random.default_rng(0))
    rows = bench.measure(cases, {1: 5, bench.BATCH: 2}, repeats=1)
    assert rows[0]["ratio"] == 1.0 and len(rows) == 6
    assert "per-filter P" in bench.format_table(rows)
