"""Smoke test of benchmarks/estimator_throughput.py: checks pass on small sizes, table prints."""

import pytest
from benchmark_module import load_benchmark

pytest.importorskip("filterpy")

bench = load_benchmark("estimator_throughput")


def test_checks_pass_on_small_sizes():
    system = bench.random_system()
    checks = [bench.batch_vs_single(system, adaptive=False, batch=64, steps=40, rows=4),
              bench.batch_vs_single(system, adaptive=True, batch=64, steps=40, rows=4),
              bench.ours_vs_filterpy(system, steps=50),
              bench.shared_vs_alone(system, adaptive=False, batch=32, steps=60),
              bench.shared_vs_alone(system, adaptive=True, batch=32, steps=60),
              bench.float32_batch(50, 50),
              bench.float32_sequential(300, chunk=128)]
    assert all(c["passed"] for c in checks), bench.format_checks(checks)


def test_table_has_every_row_with_its_target():
    steps = {1: 5, **{n: 2 for n in bench.BATCHES}}
    cases = bench.build_cases(bench.random_system(), steps, bench.np.random.default_rng(0))
    rows = bench.measure(cases, steps, repeats=1)
    assert rows[0]["ratio"] == 1.0 and len(rows) == 2 + 4 * len(bench.BATCHES)
    assert {(r["filter"], r["N"]) for r in rows} >= {
        ("KalmanFilter, 10% dropout", 256), ("AdaptiveKalmanFilter", 256),
        ("KalmanFilter", 1024)}
    table = bench.format_table(rows)
    assert "per-filter P" in table and ">= 45x" in table and ">= 1e+06/s" in table
