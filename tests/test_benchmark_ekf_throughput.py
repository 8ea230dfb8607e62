"""Smoke test of benchmarks/ekf_throughput.py: the batch equals its filters alone, table prints."""

from benchmark_module import load_benchmark

bench = load_benchmark("ekf_throughput")


def test_batch_equals_filters_alone_and_table_prints():
    record = bench.closed_loop_record(12)
    check = bench.batch_equals_alone(record, batch=8, steps=12, rows=2)
    assert check["passed"], check["detail"]
    rows = bench.measure(record, {1: 4, 256: 3}, loop_filters=1, repeats=1)
    assert rows[0]["ratio"] == 1.0 and rows[1]["N"] == 256
    assert "goal" in bench.format_table(rows)
