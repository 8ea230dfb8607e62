"""Changes in mid-record (:mod:`estimators.diagnosis.changes`): detected and dated as changes,
never reported on a record whose dynamics do not change."""

from __future__ import annotations

import pytest

from estimators.diagnosis import diagnose, synthesize, typical_effect
from estimators.diagnosis.changes import detect
from estimators.diagnosis.residuals import estimate
from marine_envs.models import get_model
from marine_envs.models.effects import Effect

DURATION = 300.0


def _residuals(effects: tuple[Effect, ...], seed: int):
    recording = synthesize("usv", effects, duration=DURATION, noise=0.05, seed=seed)
    return recording, estimate(recording, get_model("usv"))


@pytest.fixture(scope="module")
def yaw_damping_change() -> Effect:
    """The USV's yaw damping grows by half at 40 % of the record (the yaw rate's motion changes
    by 22 % RMS)."""
    typical = typical_effect("usv", "parameter_change", "r", duration=DURATION, seed=1)
    return Effect("parameter_change", "r", {"time": 120.0, "what": "damping",
                                            "c": 3 * typical.parameters["c"]})


def test_a_damping_change_is_detected_dated_and_sized(yaw_damping_change):
    _, res = _residuals((yaw_damping_change,), seed=1)
    changes = detect(res)
    assert changes, "the change was not detected"
    top, truth = changes[0], yaw_damping_change.parameters
    assert (top.target, top.what) == ("r", "damping")
    assert abs(top.time - truth["time"]) <= 0.1 * DURATION
    assert abs(top.time - truth["time"]) <= 3 * top.time_std + res.dt
    assert top.c == pytest.approx(truth["c"], rel=0.3)
    assert top.after < top.before < 0  # more damping after: the derivative grows more negative
    assert top.p_value <= 0.01


def test_the_diagnosis_names_the_change_in_words(yaw_damping_change):
    recording, _ = _residuals((yaw_damping_change,), seed=1)
    diagnosis = diagnose(recording, "usv")
    top = diagnosis.findings[0]
    assert (top.effect, top.target) == ("parameter_change", "r")
    assert abs(top.parameters["time"] - 120.0) <= 0.1 * DURATION
    assert top.std["time"] > 0
    assert "the damping of r changes at t = " in top.explanation
    assert "goes from" in top.explanation and "1/s" in top.explanation


@pytest.mark.parametrize("seed", [100, 101])
def test_an_effect_free_record_has_no_change(seed):
    assert detect(_residuals((), seed)[1]) == []


def test_a_steady_quadratic_damping_is_not_a_change():
    # a drag that acts all along fits both halves: its equation's steady terms take it
    drag = typical_effect("usv", "quadratic_damping", "r", duration=DURATION, seed=1)
    assert detect(_residuals((drag,), seed=1)[1]) == []
