"""What a free-simulation finding may claim (issue 58, item 3): the range it was fitted over, no
term whose sign makes the motion less stable than the linear model, an offset named as the
model's offset, an actuator effect on a measured input named as standing in for dynamics.
Seeded synthetic zigzags of a Nomoto ship whose truth is known."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from estimators.diagnosis import diagnose
from estimators.diagnosis.free_simulation_report import markdown
from estimators.diagnosis.ranges import outside_range
from marine_envs.models import get_model
from marine_envs.models.integrate import rk4
from marine_envs.recording import Recording


def zigzag(amplitude: float, delta0: float = 0.0, lag: float = 0.0, c2: float = 0.0,
           K: float = -0.1, T: float = 8.0, duration: float = 120.0, dt: float = 0.2,
           seed: int = 0) -> Recording:
    """A zigzag amplitude/amplitude (deg) of a Nomoto ship, rudder rate 15 deg/s, whose truth
    has a rudder offset ``delta0`` (rad), yaw dynamics of second order (the rudder's yaw moment
    lags the rudder by a first-order ``lag``, s) and a yaw damping ``c2 r|r|`` added to r'; the
    rudder angle itself is logged (``meta["measured_inputs"]``), r and psi with small noise."""
    ship = get_model("nomoto", K=K, T=T, delta0=delta0)
    rate, a = math.radians(15.0) * dt, math.radians(amplitude)
    z, delta, order = np.zeros((1, 3)), 0.0, a  # r, psi, the rudder as the yaw moment sees it
    rows = []
    for k in range(int(duration / dt)):
        if order > 0 and -z[0, 1] >= a:  # K < 0: a positive rudder turns to negative psi
            order = -a
        elif order < 0 and -z[0, 1] <= -a:
            order = a
        delta += float(np.clip(order - delta, -rate, rate))
        rows.append((k * dt, delta, z[0, 0], z[0, 1]))
        if not lag:
            z[0, 2] = delta

        def f(s: np.ndarray, t: float, delta: float = delta) -> np.ndarray:
            out = np.empty_like(s)
            out[:, :2] = ship.rhs(s[:, :2], s[:, 2:])
            out[:, 0] += c2 * s[:, 0] * np.abs(s[:, 0])
            out[:, 2] = (delta - s[:, 2]) / lag if lag else 0.0
            return out

        z = rk4(f, z, dt / 4, 4)
    data = pd.DataFrame(rows, columns=["time", "delta", "r", "psi"])
    rng = np.random.default_rng(seed)
    data[["r", "psi"]] += 1e-4 * rng.standard_normal((len(data), 2))
    return Recording(data, model="nomoto", meta={"measured_inputs": ["delta"]})


def test_a_rudder_offset_is_named_as_the_models_delta0_with_the_range_it_was_fitted_on():
    record = zigzag(10.0, delta0=math.radians(-0.5), seed=1)
    diagnosis = diagnose([record], "nomoto", calibrate="K,T", method="free")
    (finding,) = diagnosis.findings
    assert (finding.effect, finding.target) == ("current", "r")  # the catalogue's term ...
    named = diagnosis.to_dict()["findings"][0]["named_as"]  # ... named as what it is
    assert named["as"] == "rudder offset" and named["parameter"] == "delta0"
    assert math.degrees(named["value"]) == pytest.approx(-0.5, abs=0.05)
    assert "rudder offset of -0.5 ± " in finding.explanation
    assert "not a current" in finding.explanation
    assert not finding.explanation.startswith("a steady force or current")
    # the range: the yaw rate the term acted on, as the fitted model simulated the record
    low, high = diagnosis.to_dict()["findings"][0]["fitted_range"]["r"]
    r = record.measurements[:, record.measured_names.index("r")]
    assert low == pytest.approx(r.min(), abs=0.05 * np.ptp(r))
    assert high == pytest.approx(r.max(), abs=0.05 * np.ptp(r))
    report = markdown(diagnosis)
    assert "current (rudder offset)" in report and "r in [" in report and "deg/s" in report


def test_outside_range_names_the_quantity_a_record_takes_beyond_the_fitted_range():
    finding = {"effect": "nonlinear_damping", "target": "r", "fitted_range": {"r": [-0.02, 0.03]}}
    inside = {"r": np.array([-0.021, 0.0, 0.0305]), "psi": np.array([5.0])}
    assert outside_range(finding, inside) == []  # within the margin: the same amplitude
    (message,) = outside_range(finding, {"r": np.array([-0.01, 0.06])}, {"r": "rad/s"})
    assert "nonlinear_damping on r" in message and "[-1.15, 1.72] deg/s" in message
    assert "[-0.573, 3.44] deg/s" in message
    assert outside_range({"effect": "current", "target": "r"}, {"r": np.ones(3)}) == []


def test_a_damping_that_falls_with_amplitude_is_refused_as_non_physical():
    # the truth's yaw damping falls from 1/T = 0.125 1/s at r = 0 by about 0.07 1/s at the
    # largest yaw rate recorded (0.8 r|r|): the fit finds it, the diagnosis refuses to claim it
    # and takes the next admissible candidate (here the rudder offset the truth also has)
    series = [zigzag(a, c2=0.8, delta0=math.radians(-0.5), seed=k)
              for k, a in enumerate((10.0, 20.0))]
    diagnosis = diagnose(series, "nomoto", calibrate="K,T", method="free")
    refused = {t["candidate"]: t for t in diagnosis.to_dict()["non_physical"]}
    assert "quadratic_damping(r)" in refused
    reason = refused["quadratic_damping(r)"]["reason"]
    assert reason.startswith("non-physical") and "linear damping" in reason
    assert refused["quadratic_damping(r)"]["improvement"] > 0.2  # it would have been taken
    assert all(f.effect not in ("quadratic_damping", "nonlinear_damping") or
               f.parameters["c"] < 0 for f in diagnosis.findings)
    assert diagnosis.findings and diagnosis.findings[0].named_as["as"] == "rudder offset"
    assert "Refused as non-physical" in markdown(diagnosis)


def test_a_delay_on_the_measured_rudder_is_named_as_standing_in_for_yaw_dynamics():
    # second-order yaw dynamics (the rudder's moment lags 1.5 s): the first-order host model
    # takes a delay on the rudder, which was measured and cannot lag itself
    series = [zigzag(a, lag=1.5, seed=k) for k, a in enumerate((10.0, 20.0))]
    diagnosis = diagnose(series, "nomoto", calibrate="K,T", method="free")
    top = diagnosis.findings[0]
    assert (top.effect, top.target) == ("input_delay", "delta")
    assert top.named_as == {"as": "missing dynamics", "input": "delta", "measured": True}
    assert "stands in for dynamics" in top.explanation and "cannot lag" in top.explanation
    assert "transport delay" not in top.explanation
    assert top.fitted_range["delta"] == pytest.approx([-math.radians(20), math.radians(20)],
                                                      abs=1e-3)
