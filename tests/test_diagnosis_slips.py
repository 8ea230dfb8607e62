"""A user's slips answered before any work, and records sized so memory stays bounded."""

import json
import re

import numpy as np
import pytest

from agents.cli import main
from agents.simulate import simulate
from estimators.diagnosis import diagnose, sizing
from estimators.diagnosis.report import welch
from marine_envs.models import get_model
from marine_envs.recording import Recording, write_recording


@pytest.fixture(scope="module")
def usv():
    """An effect-free USV record under its autopilot, 100 s at 10 Hz (seeded)."""
    return simulate("marine_envs/USV-v0", 1000, seed=1, policy="lqr")


def _with(rec, **columns):
    return Recording(rec.data.assign(**columns), rec.model, rec.params, rec.meta)


def _forbid_work(monkeypatch):
    """Any smoothing or free simulation fails the test: the answer must come before."""
    def work(*args, **kwargs):
        raise AssertionError("the diagnosis started its work")

    monkeypatch.setattr("estimators.diagnosis.api.diagnose_seaway", work)
    monkeypatch.setattr("estimators.diagnosis.api.diagnose_series", work)


def test_the_same_recording_twice_is_refused_naming_both(usv, monkeypatch, tmp_path, capsys):
    _forbid_work(monkeypatch)
    copy = Recording(usv.data.copy(), usv.model, usv.params, {"name": "copy.csv"})
    with pytest.raises(ValueError, match=r"given twice: recording 1 .* and recording 2 "
                                         r"\(copy\.csv\) hold identical data"):
        diagnose([usv, copy])
    path = write_recording(usv, tmp_path / "run.csv")
    assert main(["diagnose", str(path), str(path), "--quiet"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("marine diagnose: error: the same recording is given twice")


@pytest.mark.parametrize("rate, angle", [("r", "psi"), ("p", "phi")])
def test_a_rate_in_degrees_per_second_is_told_and_refused(usv, monkeypatch, rate, angle):
    _forbid_work(monkeypatch)
    assert usv.warnings == []
    slipped = _with(usv, **{rate: np.degrees(usv.data[rate])})
    assert any(re.match(rf"{rate}: says {angle} turns 5[678]x more", line) and "deg/s declared "
               "as rad/s" in line for line in slipped.warnings)
    with pytest.raises(ValueError, match=rf"{rate} is 5[67]\.\dx the rate at which {angle} "
                                         rf"changes: {rate} is in deg/s"):
        diagnose(slipped)


def test_an_angle_in_degrees_is_refused_but_not_a_rate_and_angle_that_agree(usv, monkeypatch):
    _forbid_work(monkeypatch)
    with pytest.raises(ValueError, match=r"phi changes 5[67]\.\dx more than its rate p says: "
                                         r"phi is in deg"):
        diagnose(_with(usv, phi=np.degrees(usv.data["phi"])))
    # both in degrees: they agree with each other (a rate beyond its bound is told apart)
    both = _with(usv, p=np.degrees(usv.data["p"]), phi=np.degrees(usv.data["phi"]))
    assert not any(line.startswith(("p: says", "phi: turns")) for line in both.warnings)


def test_time_in_milliseconds_is_refused_before_the_work(usv, monkeypatch, tmp_path, capsys):
    _forbid_work(monkeypatch)
    slipped = _with(usv, time=usv.data["time"] * 1000)
    with pytest.raises(ValueError, match=r"sample step 100 s .* too coarse for the usv model: "
                                         r"at most 1\.5 s .* time in milliseconds"):
        diagnose(slipped)
    path = write_recording(slipped, tmp_path / "ms.csv")
    assert main(["diagnose", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1].startswith("marine diagnose: error: ms.csv: sample step 100 s")


def test_seconds_declared_as_milliseconds_are_told(usv, monkeypatch):
    _forbid_work(monkeypatch)
    with pytest.raises(ValueError, match=r"1000 samples over 0\.0999 s \(1e\+04 Hz\) is an "
                                         r"absurd rate .* time in seconds, declared as ms"):
        diagnose(_with(usv, time=usv.data["time"] / 1000))


def test_a_decimation_too_large_is_refused_naming_the_largest(usv, monkeypatch, tmp_path,
                                                              capsys):
    _forbid_work(monkeypatch)
    path = write_recording(usv, tmp_path / "run.csv")
    assert main(["diagnose", str(path), "--decimate", "100", "--quiet"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert re.search(r"error: run\.csv: sample step 10 s .* keeping every 100-th sample .* "
                     r"decimate by 15 at most", line)


def test_spectra_of_coarse_records_do_not_crash():
    # scipy's welch with nperseg=0 raised after all the work for a step above 60 s
    omega, psd = welch(np.random.default_rng(0).normal(size=400), dt=100.0)
    assert len(omega) == len(psd) > 1 and np.all(np.isfinite(psd))


@pytest.mark.parametrize("model, step", sorted(sizing.SEAWAY_STEP.items()))
def test_an_ordinary_record_is_judged_whole(model, step):
    vehicle = get_model(model)
    assert step <= sizing.coarsest_step(vehicle, 3.0)
    rec = Recording.from_arrays(model, np.arange(3001) * step,
                                np.zeros((3001, len(vehicle.input_names))),
                                {vehicle.output_names[0]: np.zeros(3001)})
    plan = sizing.plan(rec, vehicle)
    assert (plan.factor, plan.samples, plan.cut) == (1, 3001, False)


def test_a_fast_record_is_decimated_anti_aliased_and_said(usv):
    # the USV at 100 Hz, 10x faster than its step: a 7-Hz tone, beyond the new Nyquist
    # frequency (5 Hz), would fold to 3 Hz if samples were only dropped; it is filtered out
    vehicle = get_model("usv")
    time = np.arange(6000) * 0.01
    roll = 0.1 * np.sin(0.6 * time)
    tone = 0.01 * np.sin(2 * np.pi * 7.0 * time)  # folds to 3 Hz if kept
    rec = Recording.from_arrays("usv", time, 0.1 * np.sign(np.sin(0.2 * time)),
                                {"phi": roll + tone, "p": 0.06 * np.cos(0.6 * time)})
    lines = []
    out, done = sizing.sized(rec, vehicle, lines.append)
    assert done["decimated"]["factor"] == 10 and out.dt == pytest.approx(0.1)
    middle = slice(20, -20)
    assert np.abs(out.data["phi"] - 0.1 * np.sin(0.6 * out.time))[middle].max() < 1e-3
    assert lines == [f"decimated before the diagnosis: {done['decimated']['reason']} (by 10, "
                     "to a step of 0.1 s)"]


def test_a_record_beyond_the_budget_is_cut_to_its_most_excited_part(usv, monkeypatch):
    vehicle = get_model("usv")
    monkeypatch.setitem(sizing.SEAWAY_BYTES_PER_SAMPLE, "usv", sizing.MEMORY_BUDGET / 200)
    monkeypatch.setattr(sizing, "ORDINARY_SECONDS", 10.0)
    # the rudder moves only from 30 to 45 s
    moving = (usv.time >= 30) & (usv.time < 45)
    rec = _with(usv, delta=np.where(moving, usv.data["delta"], 0.0))
    out, done = sizing.sized(rec, vehicle)
    assert len(out.time) == 200 and done["cut"]["samples"] == 200
    assert done["cut"]["start"] <= 30 and done["cut"]["stop"] >= 44.9
    assert "1000 samples are more than the seaway method's budget of 200" in \
        done["cut"]["reason"]


def test_a_cut_record_says_so_in_the_diagnosis(usv, monkeypatch):
    monkeypatch.setitem(sizing.SEAWAY_BYTES_PER_SAMPLE, "usv", sizing.MEMORY_BUDGET / 700)
    monkeypatch.setattr(sizing, "ORDINARY_SECONDS", 10.0)
    lines = []
    diagnosis = diagnose(usv, log=lines.append)
    assert diagnosis.mismatch is not None
    document = json.loads(diagnosis.to_json())
    assert document["record"]["cut"]["samples"] == 700
    assert diagnosis.residuals is not None and len(diagnosis.residuals.time) == 700
    assert any(line.startswith("cut before the diagnosis: 1000 samples") for line in lines)
