"""The measured recordings shipped in marine_envs/data/real (written by
examples/convert_real_data.py): format, licences, the physics they are known to contain, and
what the mismatch diagnosis says of them."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scipy import signal

from marine_envs.models import get_model
from marine_envs.models.integrate import rk4
from marine_envs.recording import read_recording

REAL = Path(str(files("marine_envs") / "data" / "real"))
KVLCC2 = REAL / "kvlcc2_roll_decay.csv"
HOVER_RUNS = ("2019-04-16-11-24-59", "2019-04-16-11-28-36")
HOVER = [REAL / f"hovercraft_epfl_{run}.csv" for run in HOVER_RUNS]
HOVER_PARAMS = REAL / "hovercraft_epfl_params.json"
DT = 0.1


# -- helpers -------------------------------------------------------------------------------------
def extrema(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Alternating extrema (the first sample if it is one), refined by a parabola."""
    idx = np.sort(np.r_[signal.find_peaks(x)[0], signal.find_peaks(-x)[0]])
    if abs(x[0]) >= abs(x[1]):
        idx = np.r_[0, idx]
    times, values = [], []
    for i in idx:
        if 0 < i < len(x) - 1:
            a, b, c = x[i - 1], x[i], x[i + 1]
            off = 0.5 * (a - c) / (a - 2 * b + c)
            times.append(t[i] + off * (t[1] - t[0]))
            values.append(b - 0.25 * (a - c) * off)
        else:
            times.append(t[i])
            values.append(x[i])
    return np.asarray(times), np.asarray(values)


def decay(t: np.ndarray, x: np.ndarray):
    """Extremum times, peak-to-peak heights, per-period log decrements and their amplitudes."""
    te, ve = extrema(t, x)
    height = np.abs(np.diff(ve))
    return te, height, np.log(height[:-2] / height[2:]), 0.25 * (height[:-2] + height[2:])


def assert_uniform_10hz(time: np.ndarray) -> None:
    assert time[0] == 0.0
    np.testing.assert_allclose(np.diff(time), DT, rtol=0, atol=1e-9)


# -- files and licences --------------------------------------------------------------------------
def test_every_shipped_file_exists_with_its_licence_and_is_small():
    for path in [KVLCC2, *HOVER]:
        assert path.is_file(), path
        assert path.with_name(path.name + ".json").is_file(), path
        assert path.stat().st_size < 300_000, path
    assert HOVER_PARAMS.is_file()
    readme = (REAL / "README.md").read_text(encoding="utf-8")
    for name in (KVLCC2.name, *(p.name for p in HOVER), HOVER_PARAMS.name):
        assert name in readme, name
    for licence, holder in (("LICENSE-kvlcc2", "Martin Alexandersson"),
                            ("LICENSE-hovercraft-epfl", "Mauro Pfister")):
        text = (REAL / licence).read_text(encoding="utf-8")
        assert "MIT License" in text and holder in text
        assert "Permission is hereby granted, free of charge" in text


@pytest.mark.parametrize("path", [KVLCC2, *HOVER], ids=lambda p: p.stem)
def test_sidecars_carry_source_licence_and_sample_rate(path):
    rec = read_recording(path)
    assert rec.meta["licence"] == "MIT"
    assert rec.meta["sample_rate_hz"] == 10.0
    holder = "Martin Alexandersson" if path == KVLCC2 else "Mauro Pfister"
    assert holder in rec.meta["source"] and rec.meta["description"]


# -- KVLCC2 roll decay ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def kvlcc2():
    return read_recording(KVLCC2)


def test_kvlcc2_is_a_roll_only_decay_at_10_hz_starting_at_the_release(kvlcc2):
    assert kvlcc2.model == "usv"
    assert kvlcc2.measured_names == ("phi",)
    assert_uniform_10hz(kvlcc2.time)
    assert kvlcc2.time[-1] > 180.0
    np.testing.assert_array_equal(kvlcc2.inputs, 0.0)  # no rudder in a decay test
    phi = kvlcc2.data["phi"].to_numpy()
    assert np.argmax(np.abs(phi)) == 0  # cut at the release
    assert 9.5 < np.degrees(abs(phi[0])) < 11.0
    assert abs(np.degrees(phi[-600:].mean())) < 0.05  # tail mean removed


def test_kvlcc2_roll_decays_and_its_damping_depends_on_amplitude(kvlcc2):
    _, height, dec, amp = decay(kvlcc2.time, kvlcc2.data["phi"].to_numpy())
    # successive peaks decrease: strictly in the first 60 s (~47 half periods), and the
    # envelope (mean over blocks of 10 periods) all the way to the end
    assert np.all(np.diff(height[:47]) < 0)
    blocks = height[: len(height) // 20 * 20].reshape(-1, 20).mean(axis=1)
    assert len(blocks) >= 6 and np.all(np.diff(blocks) < 0)
    assert height[-1] < 0.15 * height[0]
    # amplitude-dependent damping: the first periods (~10 deg) decay much faster than the
    # small-amplitude ones (< 2 deg) - a linear model's decrement would be constant
    first = np.log(height[0] / height[6]) / 3  # the first three periods, ~10 deg
    small = dec[np.degrees(amp) < 2.0].mean()
    assert first > 1.5 * small > 0
    assert np.corrcoef(amp, dec)[0, 1] > 0.5


def test_kvlcc2_params_are_the_log_decrement_estimate_and_the_linear_model_misses_the_tail(
        kvlcc2):
    te, height, _, _ = decay(kvlcc2.time, kvlcc2.data["phi"].to_numpy())
    wn, zeta = kvlcc2.params["wn"], kvlcc2.params["zeta"]
    delta = np.log(height[0] / height[6]) / 3
    np.testing.assert_allclose(zeta, delta / np.sqrt(4 * np.pi**2 + delta**2), rtol=1e-3)
    np.testing.assert_allclose(wn * np.sqrt(1 - zeta**2), 2 * np.pi * 3 / (te[6] - te[0]),
                               rtol=1e-3)
    assert 2.3 < wn < 2.7 and 0.005 < zeta < 0.012  # model scale: T ~ 2.53 s

    # The nominal model with these params, released from the first sample
    A, _, _ = get_model("usv", **kvlcc2.params).linearize()
    step = scipy.linalg.expm(A * DT)
    x = np.array([0.0, 0.0, 0.0, 0.0, kvlcc2.data["phi"].iloc[0]])
    sim = np.empty(len(kvlcc2.time))
    for k in range(len(sim)):
        sim[k] = x[4]
        x = step @ x
    phi = kvlcc2.data["phi"].to_numpy()
    start, tail = kvlcc2.time < 7.6, kvlcc2.time > kvlcc2.time[-1] - 30
    # it follows the first three periods ...
    assert np.sqrt(np.mean((sim - phi)[start] ** 2)) < 0.03 * abs(phi[0])
    # ... but decays too fast: late in the record it keeps less than half the measured motion
    assert np.abs(sim[tail]).max() < 0.5 * np.abs(phi[tail]).max()


# -- EPFL hovercraft -----------------------------------------------------------------------------
@pytest.fixture(scope="module", params=HOVER, ids=HOVER_RUNS)
def hover(request):
    return read_recording(request.param)


def test_hovercraft_recording_is_a_10_hz_prbs_run_with_pose_only(hover):
    assert hover.model == "hovercraft"
    assert hover.measured_names == ("north", "east", "psi")
    assert_uniform_10hz(hover.time)
    assert hover.time[-1] > 20.0
    s1, s2, delta = hover.inputs.T
    np.testing.assert_array_equal(delta, 0.0)
    for s in (s1, s2):
        assert set(np.unique(s)) == {0.0, 1.0}
        assert 0.3 < s.mean() < 0.7
    # lab scale: a few metres, speeds below 3 m/s, yaw unwrapped (steps well below pi)
    north, east, psi = hover.measurements.T
    assert np.abs(north).max() < 6 and np.abs(east).max() < 6
    assert np.hypot(np.diff(north), np.diff(east)).max() / DT < 3.0
    assert np.abs(np.diff(psi)).max() < 2.5
    assert np.ptp(psi) > 2 * np.pi  # it turns several times


def test_hovercraft_yaw_responds_to_differential_thrust_with_the_model_sign(hover):
    """sigma_1 (port) > sigma_2 (starboard) must yaw the craft to starboard (r_dot > 0), as
    N_P = y_P (T_1 - T_2) says; the conversion chose the mapping that does."""
    s1, s2, _ = hover.inputs.T
    psi = hover.data["psi"].to_numpy()
    r_dot = (psi[2:] - 2 * psi[1:-1] + psi[:-2]) / DT**2  # around sample k + 1
    r = (psi[2:] - psi[:-2]) / (2 * DT)
    diff = (s1 - s2)[:-2] + (s1 - s2)[1:-1]  # commands k and k + 1 act in that window
    X = np.c_[diff, r, np.ones_like(r)]
    coef, res, *_ = np.linalg.lstsq(X, r_dot, rcond=None)
    sigma2 = res[0] / (len(r_dot) - X.shape[1])
    std = np.sqrt(sigma2 * np.linalg.inv(X.T @ X)[0, 0])
    assert coef[0] > 5.0 and coef[0] / std > 8.0, (coef, std)
    # and plainly: port-only intervals speed the yaw rate up, starboard-only ones slow it down
    port, stbd = diff == 2, diff == -2
    assert r_dot[port].mean() > 10.0 > -10.0 > r_dot[stbd].mean()


def simulate(model, x0: np.ndarray, inputs: np.ndarray, substeps: int = 4) -> np.ndarray:
    """Open-loop states at the samples, each input held over its sample."""
    xs = [x0]
    for u in inputs[:-1]:
        xs.append(rk4(lambda z, _t, u=u: model.rhs(z, u), xs[-1], DT / substeps, substeps))
    return np.array(xs)


def test_hovercraft_params_bring_the_model_to_the_lab_craft_scale(hover):
    params = json.loads(HOVER_PARAMS.read_text(encoding="utf-8"))
    assert hover.params == params
    assert 0.03 < params["m"] < 0.2  # a ~60 g craft, not a 150 t LCAC
    north, east, psi = hover.measurements.T
    vn, ve, r = (np.gradient(c, DT) for c in (north, east, psi))
    u = np.cos(psi) * vn + np.sin(psi) * ve
    v = -np.sin(psi) * vn + np.cos(psi) * ve
    speed = np.hypot(vn, ve)
    x0 = np.array([u[1], v[1], r[1], north[1], east[1], psi[1]])
    lab = simulate(get_model("hovercraft", **params), x0, hover.inputs[1:])
    lab_speed = np.hypot(lab[:, 0], lab[:, 1])
    assert 0.7 < lab_speed.max() / speed.max() < 1.3
    assert 0.6 < lab_speed.mean() / speed.mean() < 1.4
    assert 0.6 < np.abs(lab[:, 2]).max() / np.abs(r).max() < 1.4
    # the LCAC parameters would make it far too fast (from no yaw rate: the LCAC's cubic yaw
    # damping is too stiff for RK4 at the lab craft's 11 rad/s)
    lcac = simulate(get_model("hovercraft"), x0 * [1, 1, 0, 1, 1, 1], hover.inputs[1:])
    assert np.hypot(lcac[:, 0], lcac[:, 1]).max() > 4 * speed.max()


# -- the diagnosis on them (the README's worked examples) ---------------------------------------
def test_kvlcc2_diagnosis_finds_amplitude_dependent_roll_physics_in_free_simulation(tmp_path):
    from agents.cli import main

    out, report = tmp_path / "kvlcc2.json", tmp_path / "report"
    assert main(["diagnose", str(KVLCC2), "--calibrate", "wn,zeta", "--json", str(out),
                 "--report", str(report)]) == 0
    saved = json.loads(out.read_text())
    assert saved["mismatch"] is True and saved["fit"]["method"] == "free simulation"
    assert saved["calibration"]["wn"] == pytest.approx(2.47, rel=0.02)
    top = saved["findings"][0]
    amplitude_dependent = {"quadratic_damping", "nonlinear_damping", "nonlinear_restoring"}
    assert top["target"] == "p" and top["effect"] in amplitude_dependent
    assert saved["fit"]["improvement"] >= 0.5
    assert (report / "report.md").is_file() and (report / "extinction.png").is_file()


def test_hovercraft_runs_are_refused_as_too_short_with_the_reason(hover):
    from estimators.diagnosis import diagnose

    diagnosis = diagnose(hover)
    assert diagnosis.mismatch is None and "too short" in diagnosis.reason
    assert diagnosis.to_dict()["reason"] == diagnosis.reason
