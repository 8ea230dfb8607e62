"""``marine reproduce hovercraft-zigzag``: the hovercraft EKF paper's staged EKF identification."""

import json

from agents.cli import main
from agents.reproduce import hovercraft_zigzag as hz


def test_reproduce_command_writes_json_and_plot(tmp_path):
    out, png = tmp_path / "r.json", tmp_path / "r.png"
    assert main(["reproduce", "hovercraft-zigzag", "--quick", "--quiet", "--json", str(out),
                 "--plot", str(png)]) == 0
    summary = json.loads(out.read_text())
    coefficients = summary["coefficients"]
    assert set(coefficients) == set(hz.LINEAR + hz.NONLINEAR)
    for name, c in coefficients.items():
        assert {"true", "estimate", "std", "rel_error", "kind"} <= set(c)
        assert c["kind"] == ("linear" if name in hz.LINEAR else "nonlinear")
        assert {"estimate", "std", "rel_error"} <= set(summary["least_squares"][name])
    # acceptance: every linear coefficient within 5 % of the truth
    for name in hz.LINEAR:
        assert abs(coefficients[name]["rel_error"]) < 0.05, (name, coefficients[name])
    # combining the zig-zags beats the document's staging on the nonlinear terms
    errors = summary["errors"]
    assert errors["ekf_joint"]["nonlinear"] < errors["ekf_document_staging"]["nonlinear"]
    stages = summary["stages"]
    assert [s["name"] for s in stages] == ["linear", "nonlinear", "joint"]
    assert stages[0]["manoeuvres"] == ["5/5"] and stages[1]["manoeuvres"] == ["15/15", "25/25"]
    assert set(stages[0]["parameters"]) == set(hz.LINEAR)
    assert "Mean |error|" in summary["comparison"]
    # the screening explains why the other coefficients are held
    screening = summary["screening"]["all_zigzags"]
    assert not screening["N_Ar"]["identifiable"] and "N_Hr" in screening["N_Ar"]["reason"]
    assert png.stat().st_size > 20_000
