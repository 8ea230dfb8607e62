"""The free-simulation diagnosis of model tests: decays and zigzag series (seeded synthetic
records whose truth is known; the real ones are in benchmarks/real_recordings.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from estimators.diagnosis import diagnose, output_error
from estimators.diagnosis.free_simulation_report import markdown
from estimators.diagnosis.modes import decay_analysis, model_modes, nearest_mode
from estimators.diagnosis.output_error import Coordinates, Series, Structure, basis
from marine_envs.models import get_model
from marine_envs.models.effects import Effect, EffectModel
from marine_envs.models.integrate import rk4
from marine_envs.recording import Recording, read_recording

REAL = Path(__file__).resolve().parents[1] / "marine_envs" / "data" / "real"


def decay(effects=(), wn=1.0, zeta=0.02, phi0=0.3, duration=60.0, dt=0.1, noise=1e-4,
          seed=0) -> Recording:
    """A free roll decay of the USV (only phi measured) with ``effects`` in the truth."""
    truth = EffectModel(get_model("usv", wn=wn, zeta=zeta), effects)
    n = int(round(duration / dt)) + 1
    x, u = np.array([0.0, 0.0, 0.0, 0.0, phi0]), np.zeros(1)
    phi = np.empty(n)
    for k in range(n):
        phi[k] = x[4]
        x = rk4(lambda z, t: truth.rhs(z, u, None, t), x, dt / 4, 4)
    phi += noise * np.random.default_rng(seed).standard_normal(n)
    time = np.arange(n) * dt
    return Recording(pd.DataFrame({"time": time, "delta": 0.0, "phi": phi}), model="usv")


def zigzag(amplitude: float, c3: float = 0.0, K: float = -0.1, T: float = 8.0,
           duration: float = 100.0, dt: float = 0.2, seed: int = 0,
           command: bool = False, gust: float = 0.0) -> Recording:
    """A zigzag amplitude/amplitude of a Nomoto ship with a Norrbin term ``c3 r^3``, rudder
    rate 15 deg/s, r and psi measured with small noise; the recorded rudder is the actual one,
    or the (square-wave) command. ``gust``: the amplitude (rad/s^2) of a slow yaw moment of the
    wind, ``w_r``, recorded as a column of its own."""
    truth = EffectModel(get_model("nomoto", K=K, T=T),
                        [Effect("nonlinear_damping", "r", {"c": c3})] if c3 else [])
    rate, a = math.radians(15.0) * dt, math.radians(amplitude)
    x, delta, order = np.zeros(2), 0.0, a
    rows = []
    for k in range(int(duration / dt)):
        heading = -x[1]  # K < 0: a positive rudder turns to negative psi
        if order > 0 and heading >= a:
            order = -a
        elif order < 0 and heading <= -a:
            order = a
        delta += float(np.clip(order - delta, -rate, rate))
        w = np.array([gust * math.sin(2 * math.pi * k * dt / 60.0)])
        rows.append((k * dt, order if command else delta, w[0], x[0], x[1]))  # held over a step
        u = np.array([delta])
        x = rk4(lambda z, t, u=u, w=w: truth.rhs(z, u, w, t), x, dt / 2, 2)
    data = pd.DataFrame(rows, columns=["time", "delta", "w_r", "r", "psi"])
    data = data if gust else data.drop(columns="w_r")
    rng = np.random.default_rng(seed)
    data["r"] += 1e-4 * rng.standard_normal(len(data))
    data["psi"] += 1e-4 * rng.standard_normal(len(data))
    return Recording(data, model="nomoto")


# -- reading a decay ------------------------------------------------------------------------------
def test_decay_analysis_reads_a_linear_decay():
    rec = decay(wn=1.2, zeta=0.03, noise=0.0)
    found = decay_analysis(rec.time, rec.measurements[:, 0], 1e-6)
    assert found.omega_n == pytest.approx(1.2, rel=0.01)
    assert found.zeta == pytest.approx(0.03, rel=0.05)
    amplitude, decrement = found.extinction()
    assert np.ptp(decrement) < 0.01  # linear damping: the extinction curve is flat


def test_no_extremum_is_lost_and_the_cut_last_half_cycle_is_not_read():
    """601 samples: the tail's median is one of them, exactly at the offset near a crossing."""
    t = np.arange(0.0, 60.05, 0.1)
    y = np.exp(-0.05 * t) * (np.cos(t) + 0.05 * np.sin(t))
    found = decay_analysis(t, y, 1e-4)
    assert np.allclose(np.diff(found.times), np.pi, atol=0.01)
    assert found.times[-1] < t[-1] - 1.0
    mid_swing = decay_analysis(t, np.exp(-0.05 * t) * np.cos(t + 0.7), 1e-4)
    peak = np.pi - 0.7 - np.arctan(0.05)  # the first extremum, not the first sample
    assert mid_swing.times[0] == pytest.approx(peak, abs=0.01)


def test_model_modes_are_the_ones_the_channels_see():
    usv = get_model("usv", wn=0.8, zeta=0.1)
    roll = [m for m in model_modes(usv, ["phi"]) if m[1] < 1]
    assert roll == [pytest.approx((0.8, 0.1))]
    assert all(m[1] >= 1 for m in model_modes(get_model("nomoto"), ["r"]))
    rov = get_model("rov")  # an unstable real pole at 1.01 1/s (zeta -1) is no oscillation
    assert abs(nearest_mode(rov, rov.state_names, 1.0)[1]) < 1


def test_batched_simulation_equals_one_simulation_per_parameter_set():
    series = Series.from_recordings([decay()], get_model("usv"), ["wn", "zeta"])
    structure = Structure(series, ("wn", "zeta"), (basis("quadratic_damping", "p"),))
    theta = np.tile(structure.start(), (3, 1))
    theta[:, 0] = [0.8, 1.0, 1.2]
    theta[:, 2] = [0.0, -0.3, -1.0]
    batch = structure.simulate(theta, 0)
    for row, values in zip(batch, theta, strict=True):
        np.testing.assert_allclose(row, structure.simulate(values[None], 0)[0], rtol=1e-12)


@pytest.mark.parametrize("vehicle, names, terms", [
    ("usv", ("wn", "zeta"), (basis("quadratic_damping", "p"),
                             basis("nonlinear_restoring", "p", source="phi"),
                             basis("coupling", "p", source="phi"))),
    ("nomoto", ("K", "T"), (basis("linear_damping", "r"),
                            basis("nonlinear_damping", "r", form="cubic"),
                            basis("current", "r"), basis("sensor_bias", "psi"))),
    ("hovercraft", ("N_Hr",), (basis("quadratic_damping", "r"),))])
def test_the_compiled_free_simulation_is_the_numpy_one(monkeypatch, vehicle, names, terms):
    """Every term the compiled simulation knows, parameters per row (packed per row, or one
    model per row where the model takes no parameter per row) and an input effect per row."""
    if vehicle == "hovercraft":  # a shipped EPFL run (3 inputs, north/east/psi measured)
        rec = read_recording(sorted(REAL.glob("hovercraft_epfl_2019-*.csv"))[0])
        model = get_model(vehicle, **rec.params)
    else:
        rec = decay() if vehicle == "usv" else zigzag(20.0, duration=60.0)
        model = get_model(vehicle)
    series = Series.from_recordings([rec], model, names)
    structure = Structure(series, names, terms)
    theta = np.tile(structure.start(), (3, 1))
    theta[:, 0] *= [0.8, 1.0, 1.2]
    theta[:, len(names):len(names) + len(terms)] = [[0.0] * len(terms), [0.1] * len(terms),
                                                    [-0.2] * len(terms)]
    actuators = [[], [Effect("input_delay", model.input_names[0], {"tau": 0.3})], []]
    compiled = structure.simulate(theta, 0, actuators=actuators)
    monkeypatch.setattr(output_error, "_compiled_states", lambda *_args: None)
    numpy = structure.simulate(theta, 0, actuators=actuators)
    np.testing.assert_allclose(compiled, numpy, rtol=1e-10, atol=1e-12)


# -- decays ---------------------------------------------------------------------------------------
def test_amplitude_dependent_damping_is_found_from_a_wrong_start():
    rec = decay([Effect("quadratic_damping", "p", {"c": -0.4})])
    # the USV's defaults (wn 0.63, zeta 0.094) are far from the truth (1.0, 0.02)
    diagnosis = diagnose(rec, "usv", calibrate="wn,zeta")
    assert diagnosis.fit["method"] == "free simulation"
    assert diagnosis.calibration["wn"] == pytest.approx(1.0, rel=0.02)
    top = diagnosis.findings[0]
    assert (top.effect, top.target) in {("quadratic_damping", "p"), ("nonlinear_damping", "p")}
    assert diagnosis.fit["improvement"] >= 0.5
    if top.effect == "quadratic_damping":
        assert top.parameters["c"] == pytest.approx(-0.4, rel=0.3)


def test_a_linear_decay_is_explained_and_nothing_is_claimed():
    diagnosis = diagnose(decay(noise=3e-4, seed=3), "usv", calibrate="wn,zeta")
    assert diagnosis.mismatch is False
    assert not diagnosis.findings
    quality = diagnosis.calibration_quality["parameters"]
    assert quality["zeta"]["value"] == pytest.approx(0.02, rel=0.1)
    assert all(q["status"] == "identified" for q in quality.values())


def test_the_same_answer_at_another_sample_rate():
    effect = [Effect("quadratic_damping", "p", {"c": -0.4})]
    answers = [diagnose(decay(effect, dt=dt), "usv", calibrate="wn,zeta") for dt in (0.1, 0.02)]
    assert answers[0].findings[0].effect == answers[1].findings[0].effect
    assert answers[0].calibration["wn"] == pytest.approx(answers[1].calibration["wn"], rel=2e-3)


def test_a_parameter_the_record_cannot_see_is_said_to_be_unidentifiable():
    diagnosis = diagnose(decay(), "usv", params={"wn": 1.0, "zeta": 0.02},
                         calibrate="zeta,Kdr")
    status = diagnosis.calibration_quality["parameters"]["Kdr"]["status"]
    assert status.startswith("not identifiable")
    assert "not identifiable" in diagnosis.summary()


def test_a_model_with_the_wrong_natural_frequency_is_named_with_the_parameter_to_set():
    diagnosis = diagnose(decay(), "usv")  # wn 0.63 in the model, 1.0 in the record
    assert diagnosis.mismatch is None
    assert "1 rad/s" in diagnosis.reason and "calibrate wn" in diagnosis.reason


# -- a zigzag series ------------------------------------------------------------------------------
def test_norrbin_damping_is_found_across_a_zigzag_series():
    series = [zigzag(a, c3=-3.0, seed=k) for k, a in enumerate((10.0, 20.0, 35.0))]
    diagnosis = diagnose(series, "nomoto", calibrate="K,T")
    top = diagnosis.findings[0]
    assert top.target == "r" and top.effect in {"nonlinear_damping", "quadratic_damping"}
    assert "leave one recording out" in diagnosis.fit["validation"]
    assert diagnosis.fit["improvement"] >= 0.3
    assert diagnosis.fit["after"]["rmse"]["psi"] < 0.5 * diagnosis.fit["before"]["rmse"]["psi"]
    # Norrbin's form per unit inertia, r' = -r/T - B3 r^3 + (K/T) delta: K = -0.1, T = 8 s
    assert top.standard_form["B1"] == pytest.approx(1 / 8.0, rel=0.05)
    assert top.standard_form["B3"] == pytest.approx(3.0, rel=0.1)
    assert top.standard_form["G_delta"] == pytest.approx(-0.1 / 8.0, rel=0.05)
    assert "r³ - 0.0125 delta" in markdown(diagnosis)  # the report's final equation


def test_a_lag_is_fitted_in_coordinates_that_pass_through_instability():
    coordinates = Coordinates(get_model("nomoto"), ["K", "T", "r0[0]"], [0, 1, 2])
    theta = np.array([-0.1, 8.0, 0.01])
    np.testing.assert_allclose(coordinates.solver(theta), [-0.1 / 8.0, 1 / 8.0, 0.01])
    np.testing.assert_allclose(coordinates.unknowns(coordinates.solver(theta)), theta)
    eps, D = 1e-7, coordinates.derivative(theta)
    numeric = np.stack([(coordinates.solver(theta + eps * e) - coordinates.solver(theta - eps * e))
                        / (2 * eps) for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(D, numeric, rtol=1e-6, atol=1e-12)
    # 1/T through zero: the same gain K/T on both sides, T from +inf to -inf, never infinite
    near = coordinates.unknowns(np.array([[-0.0125, 1e-15, 0.0], [-0.0125, -1e-15, 0.0]]))
    assert np.all(np.isfinite(near)) and near[0, 1] > 0 > near[1, 1]
    np.testing.assert_allclose(near[:, 0] / near[:, 1], -0.0125)


def test_a_course_unstable_ship_held_by_norrbin_damping_is_found_from_a_stable_start():
    # T = -20 s: the linear yaw motion diverges and the r^3 term holds it; the fit starts from
    # the default stable ship (T = 10 s) and has to cross T = infinity (1/T = 0) to reach it
    series = [zigzag(a, c3=-30.0, K=0.25, T=-20.0, seed=k) for k, a in enumerate((10.0, 20.0))]
    diagnosis = diagnose(series, "nomoto", calibrate="K,T")
    top = diagnosis.findings[0]
    assert (top.effect, top.target) == ("nonlinear_damping", "r")
    assert top.standard_form["B1"] == pytest.approx(-1 / 20.0, rel=0.05)
    assert top.standard_form["B3"] == pytest.approx(30.0, rel=0.05)
    refitted = diagnosis.calibration_quality["with_findings"]
    assert refitted["T"]["value"] == pytest.approx(-20.0, rel=0.05)
    assert refitted["K"]["value"] == pytest.approx(0.25, rel=0.05)
    assert refitted["T"]["status"] == "identified"


def test_a_rudder_rate_limit_is_found_from_the_commanded_rudder():
    series = [zigzag(a, command=True, seed=k) for k, a in enumerate((10.0, 20.0))]
    diagnosis = diagnose(series, "nomoto", calibrate="K,T")
    top = diagnosis.findings[0]
    assert (top.effect, top.target) == ("input_rate_limit", "delta")
    assert math.degrees(top.parameters["rate"]) == pytest.approx(15.0, rel=0.3)


@pytest.fixture(scope="module")
def windy_series() -> list[Recording]:
    """Two zigzags swung by a slow yaw moment (period 60 s, several degrees of heading), its
    record in the column ``w_r``."""
    return [zigzag(a, gust=0.003, seed=k) for k, a in enumerate((10.0, 20.0))]


@pytest.fixture(scope="module")
def blind(windy_series):
    """The windy series diagnosed without the wind's record."""
    return diagnose([Recording(r.data.drop(columns="w_r"), model="nomoto")
                     for r in windy_series], "nomoto", calibrate="K,T")


def test_a_recorded_wind_moment_is_an_input_of_the_simulated_model(windy_series, blind):
    # without its record the free simulation cannot follow; with it the nominal model
    # explains the series
    told = diagnose(windy_series, "nomoto", calibrate="K,T")
    assert told.measured_disturbances == ("w_r",)
    assert told.mismatch is False, told.summary()
    assert told.calibration["K"] == pytest.approx(-0.1, rel=0.05)
    assert blind.fit["before"]["rmse"]["psi"] > 5 * told.fit["before"]["rmse"]["psi"]


def test_a_series_must_measure_the_same_channels():
    a, b = zigzag(10.0), zigzag(20.0)
    b = Recording(b.data.drop(columns=["r"]), model="nomoto")
    with pytest.raises(ValueError, match="same channels"):
        diagnose([a, b], "nomoto")


def test_an_unexplained_series_says_why_each_last_candidate_was_not_kept(blind):
    # a slow yaw moment nobody recorded: no catalogue term follows it, and each candidate of
    # the last round carries its reason (diverged, not significant or too small a gain)
    assert blind.unexplained and blind.not_kept
    reasons = ("diverges", "not significant", "not identifiable", "less than the 20%")
    for tried in blind.not_kept:
        assert any(reason in tried["reason"] for reason in reasons), tried
    assert {t["candidate"] for t in blind.not_kept} >= {"nonlinear_damping(r)", "current(r)"}
    assert blind.to_dict()["not_kept"] == blind.not_kept
    assert "not kept: current(r)" in blind.summary()
    assert "why none was kept" in markdown(blind)
