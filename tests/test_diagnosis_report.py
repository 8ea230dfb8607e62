"""The mismatch report (Markdown, figures, JSON) and the ``marine diagnose`` command."""

import json

import pytest

from agents.cli import main
from estimators.diagnosis import diagnose
from estimators.diagnosis.report import write_report
from estimators.diagnosis.synthetic import synthesize
from marine_envs.models.effects import Effect
from marine_envs.recording import write_recording

PNG = b"\x89PNG"
#: A noise-free record of a USV whose rudder acts 1 s late: the finding is certain.
DELAY = Effect("input_delay", "delta", {"tau": 1.0})
JSON_KEYS = {"model", "mismatch", "channels", "windows", "band", "findings", "fit"}
FINDING_KEYS = {"effect", "target", "parameters", "std", "confidence", "improvement",
                "explanation"}


@pytest.fixture(scope="module")
def delayed(tmp_path_factory):
    """The recording's path and its diagnosis (computed once for the module)."""
    recording = synthesize("usv", [DELAY], seed=1, noise=0.0, sea=0.3, duration=150.0)
    path = write_recording(recording, tmp_path_factory.mktemp("rec") / "delayed.csv")
    return path, diagnose(recording)


@pytest.fixture(scope="module")
def short(tmp_path_factory):
    """A 20 s recording: too short to judge."""
    recording = synthesize("usv", [], seed=2, noise=0.0, sea=0.3, duration=20.0)
    return write_recording(recording, tmp_path_factory.mktemp("rec") / "short.csv")


def test_report_names_the_finding_and_draws_its_figures(delayed, tmp_path):
    path, diagnosis = delayed
    assert diagnosis.mismatch is True
    assert [(f.effect, f.target) for f in diagnosis.findings][0] == ("input_delay", "delta")
    report = write_report(diagnosis, tmp_path / "out", "delayed.csv")
    text = report.read_text()
    assert report == tmp_path / "out" / "report.md"
    assert "Mismatch found" in text and "| input_delay | delta |" in text
    assert ("tau = 1" in text or "tau = 0.9" in text) and "±" in text  # fitted, with a std
    for name in ("prediction_errors.png", "spectra.png", "finding_1_input_delay_delta.png"):
        figure = tmp_path / "out" / name
        assert f"]({name})" in text  # embedded with a relative link
        assert figure.read_bytes()[:4] == PNG and figure.stat().st_size > 10_000
    for heading in ("## Where", "## Findings", "## Held-out fit", "## How to read this"):
        assert heading in text
    saved = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert saved == diagnosis.to_dict()


def test_a_too_short_recording_gets_the_reason_only(short, tmp_path):
    diagnosis = diagnose(short)
    assert diagnosis.mismatch is None
    report = write_report(diagnosis, tmp_path)
    text = report.read_text()
    assert "Cannot judge" in text and "too short" in text and "## Findings" not in text
    saved = json.loads((tmp_path / "diagnosis.json").read_text())
    assert saved["mismatch"] is None and "too short" in saved["reason"]
    assert not list(tmp_path.glob("*.png"))


def test_cli_writes_the_documented_json_and_report(delayed, tmp_path, capsys):
    path, diagnosis = delayed
    out, report = tmp_path / "d.json", tmp_path / "report"
    assert main(["diagnose", str(path), "--json", str(out), "--report", str(report)]) == 0
    printed = capsys.readouterr()
    assert "mismatch found" in printed.out and "input_delay on delta" in printed.out
    assert "channels" in printed.out
    assert "searching the catalogue" in printed.err  # progress on stderr, not in the output
    saved = json.loads(out.read_text())
    assert JSON_KEYS <= set(saved) and saved["mismatch"] is True
    assert FINDING_KEYS <= set(saved["findings"][0])
    assert {"before", "after", "improvement", "validation", "terms"} <= set(saved["fit"])
    assert saved == diagnosis.to_dict()  # the command runs the same, deterministic diagnosis
    assert (report / "report.md").is_file() and (report / "diagnosis.json").is_file()


def test_cli_cannot_judge_a_short_recording_but_succeeds(short, tmp_path, capsys):
    out = tmp_path / "d.json"
    assert main(["diagnose", str(short), "--json", str(out)]) == 0
    assert "cannot diagnose: too short" in capsys.readouterr().out
    assert json.loads(out.read_text())["mismatch"] is None


@pytest.mark.parametrize("content, message", [
    ("[1, 2]", "must be a JSON object"),
    ("{not json", "not valid JSON"),
    ('{"wn": "fast"}', "must be numbers"),
    ('{"bogus": 1.0}', "unknown parameter(s) ['bogus']"),
])
def test_cli_rejects_a_bad_params_file(short, tmp_path, capsys, content, message):
    params = tmp_path / "params.json"
    params.write_text(content)
    assert main(["diagnose", str(short), "--params", str(params)]) == 2
    assert message in capsys.readouterr().err


def test_cli_rejects_an_unknown_model_parameter_or_file(short, tmp_path, capsys):
    assert main(["diagnose", str(short), "--model", "submarine"]) == 2
    assert "unknown model 'submarine'" in capsys.readouterr().err
    assert main(["diagnose", str(short), "--calibrate", "wn,bogus"]) == 2
    assert "calibrate: unknown parameter(s) ['bogus']" in capsys.readouterr().err
    assert main(["diagnose", str(short), "--params", str(tmp_path / "missing.json")]) == 2
    assert "missing.json: cannot read it" in capsys.readouterr().err
    assert main(["diagnose", str(tmp_path / "missing.csv")]) == 2
    assert "recording not found" in capsys.readouterr().err
