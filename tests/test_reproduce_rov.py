"""``marine reproduce rov-online-id``: the morphing-robot patent's online identification."""

import json

from agents.cli import main
from marine_envs.models.rov import SEED_COEFFICIENTS


def test_reproduce_command_writes_json_and_plot(tmp_path):
    out, png = tmp_path / "r.json", tmp_path / "r.png"
    assert main(["reproduce", "rov-online-id", "--quick", "--quiet", "--json", str(out),
                 "--plot", str(png)]) == 0
    summary = json.loads(out.read_text())
    assert set(summary["coefficients"]) == set(SEED_COEFFICIENTS)
    for record in summary["coefficients"].values():
        assert {"true_before", "true_after", "estimate_before", "estimate_after", "std_before",
                "std_after", "identifiability"} <= set(record)
    assert summary["coefficients"]["Xuu"]["true_after"] == -15.30
    assert summary["morph_time"] == 40.0
    assert summary["tracking_time_s"] < 60.0
    assert {"mean", "std", "per_seed"} <= set(summary["tracking_time_s_spread"])
    for label in ("feedforward", "nominal"):
        assert {"rms_tracking_error", "rms_tracking_error_spread"} <= set(summary[label])
    assert summary["feedforward"]["rms_tracking_error"] < \
        summary["nominal"]["rms_tracking_error"]
    assert png.stat().st_size > 50_000
