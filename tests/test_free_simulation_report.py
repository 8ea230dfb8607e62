"""The report of a model-test diagnosis (free simulation): Markdown, figures and JSON."""

import json

import numpy as np
import pandas as pd
import pytest

from estimators.diagnosis import Diagnosis, Finding, diagnose
from estimators.diagnosis.free_simulation_report import (
    display_unit,
    verdict,
)
from estimators.diagnosis.report import write_report
from marine_envs.models import get_model
from marine_envs.models.effects import Effect, EffectModel
from marine_envs.models.integrate import rk4
from marine_envs.recording import Recording

PNG = b"\x89PNG"
DT, DURATION, PHI0, NOISE = 0.1, 60.0, 0.3, 1e-4  # wn = 1 rad/s: 9.5 periods of 6.3 s
SECTIONS = ("## Verdict", "## Model check", "## Calibrated parameters", "## Findings",
            "## Held-out free simulation", "## Alternatives", "## Unexplained", "## Figures",
            "## How to read this")


def roll_decay(seed: int = 0) -> Recording:
    """A free roll decay of the USV (wn = 1 rad/s, zeta = 0.02) with quadratic roll damping
    -0.5 p|p|, released from 0.3 rad at rest; only phi measured, with white noise."""
    model = EffectModel(get_model("usv", wn=1.0, zeta=0.02),
                        [Effect("quadratic_damping", "p", {"c": -0.5})])
    n = int(round(DURATION / DT)) + 1
    x, u, phi = np.zeros(5), np.zeros(1), np.empty(n)
    x[model.model.state_names.index("phi")] = PHI0
    for k in range(n):
        phi[k] = x[4]
        x = rk4(lambda z, _t: model.rhs(z, u), x, DT / 4, 4)
    phi += NOISE * np.random.default_rng(seed).standard_normal(n)
    return Recording(pd.DataFrame({"time": np.arange(n) * DT, "delta": 0.0, "phi": phi}),
                     model="usv")


@pytest.fixture(scope="module")
def decay_diagnosis():
    return diagnose(roll_decay(), "usv", calibrate="wn,zeta", method="free")


def test_free_decay_report_has_its_sections_figures_and_json(decay_diagnosis, tmp_path):
    diagnosis = decay_diagnosis
    assert diagnosis.comparison is not None and diagnosis.mismatch is True
    assert [(f.effect, f.target) for f in diagnosis.findings] == [("quadratic_damping", "p")]
    report = write_report(diagnosis, tmp_path / "out", "decay.csv")
    text = report.read_text()
    assert report == tmp_path / "out" / "report.md"
    for heading in SECTIONS:
        assert heading in text, heading
    # the innovations report's sections do not leak in
    assert "## Where" not in text and "prediction_errors.png" not in text
    assert "Mismatch found" in text and "`quadratic_damping` on `p`" in text
    assert "| 1 | quadratic_damping | p | c = -0.5" in text and "B2 = 0.5" in text
    assert "(deg)" in text and "deg)" in text  # angles also in degrees
    assert "wn | 0.63 | 1" in text  # as set, then calibrated
    assert "record (decay of `phi`)" in text
    for name in ("time_histories.png", "simulation_errors.png", "extinction.png"):
        figure = tmp_path / "out" / name
        assert f"]({name})" in text  # embedded with a relative link
        assert figure.read_bytes()[:4] == PNG and figure.stat().st_size > 10_000
    saved = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert saved == diagnosis.to_dict() and saved["fit"]["method"] == "free simulation"


def test_verdict_names_divergence_and_what_is_left():
    finding = Finding("quadratic_damping", "p", {"c": -0.5}, {"c": 0.01}, 0.9, 0.6, "")
    diverged = Diagnosis("usv", True, findings=[finding], fit={"improvement": "diverged"})
    assert "diverges" in verdict(diverged)
    left = Diagnosis("usv", True, fit={"improvement": 0.0},
                     unexplained={"phi": {"rmse": 0.01, "share_of_signal": 0.2}})
    assert "unexplained by the catalogue" in verdict(left) and "20%" in verdict(left)
    assert "Cannot judge" in verdict(Diagnosis("usv", None, "too short"))
    assert display_unit("rad/s") == (pytest.approx(180 / np.pi), "deg/s")
    assert display_unit("m/s") == (1.0, "m/s")
