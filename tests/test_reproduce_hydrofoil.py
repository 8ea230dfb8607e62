"""The hydrofoil AKF paper's comparison: the adaptive KF against the fixed KF under LQR."""

import json

from agents.cli import main
from agents.reproduce import hydrofoil_akf


def test_akf_beats_the_fixed_kf_in_the_document_setting():
    """Table 2 of the hydrofoil AKF paper: the AKF cuts the pitch error by 38 % and the heave
    error by 7 %."""
    document = hydrofoil_akf.settings()[0]
    runs = {label: hydrofoil_akf.fly(document, label, seeds=2, steps=2400)
            for label in ("akf", "kf")}
    pitch = {k: r["pitch_rms_deg"]["mean"] for k, r in runs.items()}
    heave = {k: r["heave_rms_m"]["mean"] for k, r in runs.items()}
    assert pitch["akf"] < 0.75 * pitch["kf"]
    assert heave["akf"] < heave["kf"]
    assert runs["akf"]["failed"] == runs["kf"]["failed"] == 0
    assert 0 < runs["akf"]["time_at_Q_max"] < 0.5


def test_reproduce_command_writes_json_and_plot(tmp_path):
    out, png = tmp_path / "r.json", tmp_path / "r.png"
    assert main(["reproduce", "hydrofoil-akf", "--quick", "--quiet", "--json", str(out),
                 "--plot", str(png)]) == 0
    summary = json.loads(out.read_text())
    for name in ("akf", "kf"):
        assert {"pitch_rms_deg", "heave_rms_m", "pitch_rms_deg_spread"} <= set(summary[name])
        assert set(summary["paper"][name]) == {"pitch_rms_deg", "heave_rms_m"}
    assert summary["paper"]["akf"]["pitch_rms_deg"] == 1.178
    assert "corrected" in summary and "document" in summary["settings"]
    assert png.stat().st_size > 10_000
