"""The DP wave-frequency patent's example through ``marine reproduce dp-wave-frequency``."""

import json

from agents.cli import main


def test_reproduce_command_writes_json_and_plot(tmp_path):
    out, png = tmp_path / "r.json", tmp_path / "r.png"
    assert main(["reproduce", "dp-wave-frequency", "--quick", "--quiet", "--json", str(out),
                 "--plot", str(png)]) == 0
    s = json.loads(out.read_text())
    assert s["omega_true"] == [1.2, 1.0, 1.05] and s["omega_initial"] == [0.4, 0.4, 0.55]
    for key in ("omega_fft", "omega_estimate"):
        assert all(abs(a - b) < 0.2 for a, b in zip(s[key], s["omega_true"], strict=True))
    assert all(abs(a - b) < 0.05 for a, b in zip(s["omega_estimate"], s["omega_true"],
                                                  strict=True))
    assert s["accepted"] is True and 0 <= s["convergence_time_s"] < 300
    stats = s["seeds"]
    assert stats["runs"] == 20 and stats["fraction_within_0.05"] >= 0.85
    assert set(stats["abs_error"]) == {"omega_x", "omega_y", "omega_psi"}
    assert {"mean", "std", "per_seed"} <= set(stats["abs_error"]["omega_x"])
    assert s["seeds_600s_window"]["fraction_within_0.05"] >= 0.95
    change = s["sea_change"]
    assert change["detected_fraction"] == 1.0 and change["omega_after"] == [0.8, 0.7, 0.75]
    assert change["detection_delay_s"]["mean"] > 0
    assert s["no_wave_motion"]["accepted_fraction"] == 0.0
    assert s["settings_compared"]["document_literal"]["fraction_within_0.05"] < 0.5
    assert png.stat().st_size > 10_000
