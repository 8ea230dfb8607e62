"""``benchmarks/round_trip.py``: the table of a diagnosed decay replayed through its JSON."""

from __future__ import annotations

import math

from benchmark_module import load_benchmark

round_trip = load_benchmark("round_trip")


def test_a_synthetic_decay_round_trips_within_twice_the_held_out_error(tmp_path, capsys):
    row = round_trip.round_trip("seed 3", round_trip.synthetic_decay(3), tmp_path)
    assert (tmp_path / "seed 3.json").exists()
    assert row["passed"] and row["after"] <= 2 * row["held_out"]
    assert math.isclose(row["after"], row["by_hand"], rel_tol=1e-9)  # nothing passed by hand
    assert row["before"] > 5 * row["after"]  # the findings on the nominal parameters
    table = round_trip.format_table([row])
    assert "| seed 3 | quadratic_damping(p) |" in table and table.endswith("| PASS |")
