"""Uncertainty that covers the spread between records, and the validation across amplitude
classes (:mod:`estimators.diagnosis.spread`), on seeded synthetic records whose truth is known."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from test_diagnosis_free_simulation import decay, zigzag

from estimators.diagnosis import diagnose
from estimators.diagnosis.comparison import (
    Candidate,
    ComparisonConfig,
    Scored,
    _warm,
    all_rows,
    compare,
    extend,
)
from estimators.diagnosis.free_simulation import _diagnosis
from estimators.diagnosis.free_simulation_report import markdown
from estimators.diagnosis.output_error import Series, basis, fit
from estimators.diagnosis.spread import across_classes, amplitude_classes, pieces
from marine_envs.models import get_model
from marine_envs.models.effects import Effect
from marine_envs.recording import Recording


def lagged_zigzag(amplitude: float, check: float, K: float = -0.1, T: float = 8.0,
                  lag: float = 3.0, duration: float = 120.0, dt: float = 0.2,
                  seed: int = 0) -> Recording:
    """A zigzag amplitude/check (deg) of a Nomoto ship whose rudder acts through a first-order
    lag of ``lag`` s (a second-order yaw response, which no catalogue term of a first-order
    Nomoto model is), rudder rate 15 deg/s, r and psi measured with small noise."""
    rate, a, b = math.radians(15.0) * dt, math.radians(amplitude), math.radians(check)

    def rhs(z: np.ndarray, delta: float) -> np.ndarray:
        r, _, acting = z
        return np.array([(K * acting - r) / T, r, (delta - acting) / lag])

    x, delta, order, rows = np.zeros(3), 0.0, a, []
    for k in range(int(duration / dt)):
        heading = -x[1]  # K < 0: a positive rudder turns to negative psi
        if order > 0 and heading >= b:
            order = -a
        elif order < 0 and heading <= -b:
            order = a
        delta += float(np.clip(order - delta, -rate, rate))
        rows.append((k * dt, delta, x[0], x[1]))
        h = dt / 2
        for _ in range(2):
            k1 = rhs(x, delta)
            k2 = rhs(x + h / 2 * k1, delta)
            k3 = rhs(x + h / 2 * k2, delta)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + rhs(x + h * k3, delta))
    data = pd.DataFrame(rows, columns=["time", "delta", "r", "psi"])
    rng = np.random.default_rng(seed)
    for channel in ("r", "psi"):
        data[channel] += 1e-4 * rng.standard_normal(len(data))
    return Recording(data, model="nomoto", meta={"name": f"{amplitude:g}/{check:g} #{seed}"})


def test_the_spread_between_records_is_reported_and_covers_each_record():
    """Three decays of one condition whose cubic restoring truly differs (-0.2, -0.3, -0.4):
    the residual std of the joint fit is below that spread; the reported uncertainty is
    the spread, and every record's own value lies within two of it."""
    records = [decay([Effect("nonlinear_restoring", "p", {"c": c, "source": "phi"})],
                     phi0=0.4, duration=40.0, seed=seed)
               for seed, c in enumerate((-0.2, -0.3, -0.4))]
    d = diagnose(records, "usv", calibrate="wn,zeta", method="free")
    top = d.findings[0]
    assert (top.effect, top.target) == ("nonlinear_restoring", "p")
    spread = top.between_records["c"]
    assert len(spread["per_record"]) == 3 and spread["method"]
    assert spread["per_record"] == pytest.approx([-0.2, -0.3, -0.4], abs=0.03)
    assert spread["statistical_std"] < 0.7 * spread["spread"]  # the residuals understate it
    assert top.std["c"] == pytest.approx(spread["spread"])  # the larger is reported
    assert all(abs(v - top.parameters["c"]) <= 2 * top.std["c"] for v in spread["per_record"])
    json = d.to_dict()
    assert json["findings"][0]["between_records"]["c"]["per_record"] == spread["per_record"]
    coefficients = json["fit"]["between_records"]["coefficients"]
    assert coefficients["p: C3"]["uncertainty"] >= coefficients["p: C3"]["spread"] > 0.05
    assert "## Spread between records" in markdown(d)


def test_a_single_decay_is_cut_into_pieces_by_amplitude():
    rec = decay(phi0=0.4, zeta=0.03, duration=80.0, seed=7)
    series = Series.from_recordings([rec], get_model("usv"), ["wn", "zeta"])
    parts = pieces(series)
    assert len(parts) == 3
    starts = [float(np.max(np.abs(part.runs[0].y))) for _, part in parts]  # the envelope
    assert starts[0] > starts[1] > starts[2]  # decreasing amplitudes, at equal ratios
    assert starts[0] / starts[1] == pytest.approx(starts[1] / starts[2], rel=0.3)
    assert sum(len(part.runs[0].time) for _, part in parts) == len(series.runs[0].time)


def test_a_zigzag_series_of_two_amplitudes_is_grouped_into_its_classes():
    records = [lagged_zigzag(25, 5, seed=0), lagged_zigzag(10, 2, seed=1),
               lagged_zigzag(25, 5, seed=2, duration=100.0), lagged_zigzag(25, 15, seed=3)]
    series = Series.from_recordings(records, get_model("nomoto"), ["K", "T"])
    classes = amplitude_classes(series)
    assert [c["records"] for c in classes] == [[0, 2], [1], [3]]  # the check counts too
    assert math.degrees(classes[0]["amplitude"]["input"]) == pytest.approx(25, rel=0.02)
    assert math.degrees(classes[0]["amplitude"]["check"]) == pytest.approx(5, rel=0.15)
    assert classes[0]["label"].startswith("25/")


def test_a_correction_that_is_the_truth_holds_across_classes():
    """Zigzags 20/20 and 10/10 of a Nomoto ship with Norrbin's r^3: the diagnosis names it and
    it improves each class fitted on the other; the host model is not blamed."""
    d = diagnose([zigzag(20, c3=-30.0, seed=12), zigzag(10, c3=-30.0, seed=13)], "nomoto",
                 calibrate="K,T", method="free")
    assert [(f.effect, f.target) for f in d.findings][:1] == [("nonlinear_damping", "r")]
    across = d.across_classes
    assert len(across["classes"]) == 2 and not across["worse"] and not across["verdict"]
    assert all(row["cut"] > 0.3 for row in across["classes"])
    assert "too simple" not in markdown(d)


def test_a_correction_that_spoils_another_class_is_reported():
    """A ship with a rudder lag (second-order yaw) zigzagging 30/10 and 5/1: Norrbin's r^3 on
    the first-order model fits the series better than the calibrated linear model, yet a
    class re-run as its zig-zag by the models fitted on the other is predicted worse with it."""
    records = [lagged_zigzag(30, 10, seed=0), lagged_zigzag(30, 10, seed=1, duration=100.0),
               lagged_zigzag(5, 1, seed=2)]
    series = Series.from_recordings(records, get_model("nomoto"), ["K", "T"])
    comparison = compare(series, ["K", "T"], None, ComparisonConfig(max_findings=0))
    r3 = Candidate(basis("nonlinear_damping", "r", form="cubic"))
    wider = extend(comparison.nominal.structure, r3)
    corrected = fit(wider, all_rows(series), _warm(comparison.nominal.structure,
                                                   comparison.nominal.theta, wider))
    assert corrected.cost < 0.8 * comparison.nominal.cost  # it fits the records it saw
    scored = Scored(r3, corrected, comparison.nominal_held_out)  # the search's record of it
    comparison.rounds.append([scored])
    comparison.accepted.append(scored)
    d = _diagnosis(comparison, ["K", "T"], None)
    across = d.to_dict()["across_classes"]
    rows = {row["class"].split("/")[0]: row for row in across["classes"]}
    assert set(rows) == {"30", "5"} and rows["30"]["fitted_on"] == [rows["5"]["class"]]
    assert across["judged"] == "re-run"  # zig-zags: each class re-run as its zig-zag
    spoiled = [row for row in rows.values() if row["worse"]]
    assert spoiled and all(row["corrected"]["rerun_rmse"]["psi"]
                           > 1.1 * row["nominal"]["rerun_rmse"]["psi"] for row in spoiled)
    assert across["worse"] and "host model is too simple" in across["verdict"]
    text = markdown(d)
    assert f"makes the {spoiled[0]['class']} test worse" in text
    assert "host model is too simple" in text.split("## Model check")[0]  # in the verdict


def test_a_richer_host_is_validated_on_the_same_classes():
    """The hook for a richer host model: a series of it (here the same Nomoto model, so it
    must do exactly as the nominal-calibrated one) is fitted on the training classes and
    judged on each held-out class beside the nominal and corrected models."""
    records = [lagged_zigzag(30, 10, seed=4, duration=80.0), lagged_zigzag(5, 1, seed=5,
                                                                          duration=80.0)]
    series = Series.from_recordings(records, get_model("nomoto"), ["K", "T"])
    comparison = compare(series, ["K", "T"], None, ComparisonConfig(max_findings=0))
    r3 = Candidate(basis("nonlinear_damping", "r", form="cubic"))
    wider = extend(comparison.nominal.structure, r3)
    scored = Scored(r3, fit(wider, all_rows(series), _warm(comparison.nominal.structure,
                                                           comparison.nominal.theta, wider)),
                    comparison.nominal_held_out)
    comparison.rounds.append([scored])
    comparison.accepted.append(scored)
    across = across_classes(comparison, richer=[(series, ("K", "T"))])
    for row in across["classes"]:
        assert row["richer"]["nomoto"]["rmse"]["psi"] == pytest.approx(
            row["nominal"]["rmse"]["psi"], rel=1e-3)
    assert across["richer"]["nomoto"].startswith("nomoto does not explain them either")
