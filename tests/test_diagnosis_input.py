"""What a diagnosis makes of imperfect input: dropped samples, implausible units, its stages."""

import numpy as np
import pytest

from estimators.diagnosis import diagnose
from estimators.diagnosis.api import SEAWAY_STAGES, expected_seconds
from estimators.diagnosis.synthetic import synthesize, typical_effect
from marine_envs.recording import Recording


@pytest.fixture(scope="module")
def damped():
    effect = typical_effect("usv", "quadratic_damping", "r", strength=0.5)
    return effect, synthesize("usv", [effect], seed=1, noise=0.05, sea=0.3, duration=300)


def test_dropped_samples_are_missing_measurements_not_a_refusal(damped):
    effect, recording = damped
    data = recording.data.copy()
    rng = np.random.default_rng(0)
    for channel in ("r", "phi"):  # a logger that drops 5 % of two channels' samples
        data.loc[rng.random(len(data)) < 0.05, channel] = np.nan
    gappy = Recording(data, recording.model, recording.params, recording.meta)
    stages = []
    diagnosis = diagnose(gappy, stage=lambda name, k, n: stages.append((name, k, n)))
    top = diagnosis.findings[0]
    assert (top.effect, top.target) == ("quadratic_damping", "r")
    assert top.parameters["c"] == pytest.approx(effect.parameters["c"], rel=0.3)
    missing = gappy.missing.sum(axis=0)
    assert diagnosis.missing_samples == {"r": missing[0], "phi": missing[-1]}
    assert diagnosis.to_dict()["missing_samples"] == diagnosis.missing_samples
    assert [s[0] for s in stages] == list(SEAWAY_STAGES[1:])  # no calibration asked
    assert all(n == len(SEAWAY_STAGES) for _, _, n in stages)


def test_the_run_time_is_estimated_from_the_record_length(damped):
    _, recording = damped
    seconds = expected_seconds([recording])
    assert 1.0 < seconds < 10.0  # measured: about 3 s for these 3001 samples
    assert expected_seconds([recording.window(decimate=10)]) < seconds / 2
    assert expected_seconds([recording], method="free") is None


def test_implausible_units_reach_the_diagnosis_json():
    recording = synthesize("usv", duration=20, noise=0.05)  # too short: judged at once
    data = recording.data.assign(delta=np.degrees(recording.data["delta"]))
    diagnosis = diagnose(Recording(data, "usv", recording.params))
    assert diagnosis.mismatch is None
    (line,) = diagnosis.to_dict()["warnings"]
    assert line.startswith("delta: ") and "exceeds the model's bound 0.611 rad" in line
