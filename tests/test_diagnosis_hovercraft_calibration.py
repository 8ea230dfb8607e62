"""Free simulation that cannot follow whole records calibrates the parameters it names itself
(seeded synthetic runs of the lab-scale EPFL hovercraft, whose truth is known; the real runs
are in benchmarks/real_recordings.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from estimators.diagnosis.comparison import ComparisonConfig
from estimators.diagnosis.free_simulation import diagnose_series
from marine_envs.models import get_model
from marine_envs.models.integrate import rk4
from marine_envs.recording import Recording

#: The lab-scale hovercraft the shipped EPFL runs are converted with (the truth here).
TRUTH = json.loads((Path(__file__).resolve().parents[1] / "marine_envs" / "data" / "real"
                    / "hovercraft_epfl_params.json").read_text(encoding="utf-8"))
#: The nominal model: thrust half the truth's and yaw damping four times it.
FAR_OFF = {"T0": 0.5 * TRUTH["T0"], "N_Hr": 4.0 * TRUTH["N_Hr"]}


def run(seed: int, duration: float = 15.0, dt: float = 0.1) -> Recording:
    """A run like the EPFL ones: both thrusters switched on and off at random every sample,
    the craft spinning from the start; north, east and psi measured (mm and 0.6 deg noise)."""
    truth = get_model("hovercraft", **TRUTH)
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt))
    u = np.zeros((n, 3))
    u[:, :2] = rng.integers(0, 2, size=(n, 2))
    x = np.array([0.0, 0.0, rng.uniform(-8, 8), rng.uniform(-1, 1), rng.uniform(-1, 1),
                  rng.uniform(-3, 3)])
    states = np.empty((n, 6))
    for k in range(n):
        states[k] = x
        x = rk4(lambda z, t, uk=u[k]: truth.rhs(z, uk), x, dt / 4, 4)
    noise = {"north": 0.003, "east": 0.003, "psi": 0.01}
    measured = {c: states[:, i] + noise[c] * rng.standard_normal(n)
                for c, i in (("north", 3), ("east", 4), ("psi", 5))}
    return Recording.from_arrays("hovercraft", np.arange(n) * dt, u, measured,
                                 params={**TRUTH, **FAR_OFF}, meta={"name": f"run-{seed}"})


@pytest.fixture(scope="module")
def diagnosis():
    """The calibration and its held-out score; the search for terms is left out (time)."""
    nominal = get_model("hovercraft", **{**TRUTH, **FAR_OFF})
    return diagnose_series([run(1), run(2)], nominal, config=ComparisonConfig(max_findings=0))


def test_calibrates_instead_of_refusing(diagnosis):
    own = diagnosis.model_check["self_calibration"]
    assert own["whole_record_share"]["all"] > 0.5  # the whole runs are not followed
    assert diagnosis.mismatch is not None, diagnosis.reason
    # the parameters that are off are among those it chose by sensitivity
    assert set(FAR_OFF) <= set(own["chosen_by_sensitivity"])
    assert own["windows"] >= 4 and own["window_s"] < 15.0
    # calibrated, the windows held out (each run's in turn) are followed
    assert diagnosis.comparison.nominal_held_out.mean_square < 0.01


def test_recovers_the_truth_within_its_std(diagnosis):
    calibrated = diagnosis.calibration_quality["parameters"]
    for name, quality in calibrated.items():
        assert quality["status"] == "identified", (name, quality)
        # seeded: 0.2-0.6 std off; two std leave room for the fit's numerics
        assert abs(quality["value"] - TRUTH[name]) <= 2 * quality["std"], (name, quality)
    for name, start in FAR_OFF.items():  # and much closer to it than where it started
        assert abs(calibrated[name]["value"] - TRUTH[name]) < 0.1 * abs(start - TRUTH[name])


def test_the_json_carries_the_calibrated_values(diagnosis):
    out = diagnosis.to_dict()
    chosen = out["model_check"]["self_calibration"]["chosen_by_sensitivity"]
    for name in FAR_OFF:
        assert set(chosen[name]) >= {"value", "std", "status", "sensitivity"}
        assert out["calibration"][name] == pytest.approx(chosen[name]["value"])
