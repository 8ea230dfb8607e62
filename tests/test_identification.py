"""Parameter identification (estimators.identification): EKF, least squares, identifiability."""

import json
import math

import numpy as np
import pytest

from estimators.identification import (
    Segment,
    Stage,
    damping_signs,
    identify_ekf,
    identify_least_squares,
    identify_staged,
    noise_std,
)
from estimators.identification.joint_ekf import _fuse as fuse
from marine_envs.manoeuvres import zigzag
from marine_envs.models.hovercraft import HovercraftModel
from marine_envs.recording import Recording

CHANNELS = ("u", "v", "r", "psi")
STD = np.array([0.05, 0.05, math.radians(0.1), math.radians(0.2)])  # Hovercraft-v0's sensors
LINEAR = ("Y_Hv", "N_Hr", "N_Av", "C_R4")


def run(model, amplitude_deg, duration, seed=0, noise=STD, rudder=True):
    """A zig-zag (or, with ``rudder=False``, straight running) of ``model`` from the trim at
    32 kn, measured with white noise of std ``noise``."""
    a = math.radians(amplitude_deg)
    result = zigzag(model, a, a, dt=0.1, duration=duration)
    delta = result.rudder if rudder else np.zeros_like(result.rudder)
    if not rudder:  # hold the trim: the states stay at the nominal point
        states = np.tile(model.x0, (len(result.time), 1))
    else:
        states = result.states
    inputs = np.column_stack([np.tile(model.u0[:2], (len(delta), 1)), delta])
    rng = np.random.default_rng(seed)
    y = states[:, [0, 1, 2, 5]] + rng.normal(0.0, 1.0, (len(states), 4)) * noise
    return Segment(result.time, inputs, y, CHANNELS, angular=("psi",),
                   name=f"{amplitude_deg}/{amplitude_deg}")


@pytest.fixture(scope="module")
def model():
    return HovercraftModel()


@pytest.fixture(scope="module")
def zigzags(model):
    return [run(model, 5, 80.0, seed=1), run(model, 25, 80.0, seed=2)]


def test_ekf_identifies_the_linear_coefficients_within_5_percent(model, zigzags):
    truth = {n: getattr(model.params, n) for n in LINEAR}
    initial = {"Y_Hv": 0.5 * truth["Y_Hv"], "N_Hr": 1.5 * truth["N_Hr"],
               "N_Av": 0.5 * truth["N_Av"], "C_R4": 1.5 * truth["C_R4"]}
    result = identify_ekf(model, zigzags, LINEAR, initial=initial,
                          prior_std={n: abs(v) for n, v in truth.items()}, reference=model,
                          measurement_std=STD)
    assert np.all(np.abs(result.rel_error) < 0.05), result.table()
    assert result.identifiable.all()
    # the std is honest: errors within 3 std
    assert np.all(np.abs(result.estimate - result.reference) < 3 * result.std)
    assert result.trace.shape == (len(zigzags[0].time), 4)
    json.dumps(result.to_dict())


def test_staged_identification_chains_the_stages(model, zigzags):
    stages = [Stage("linear", zigzags[:1], ("Y_Hv", "N_Hr", "C_R4")),
              Stage("nonlinear", zigzags[1:], ("N_Hrrr",), prior="posterior")]
    first, second = identify_staged(model, stages, initial={"N_Hrrr": 0.0},
                                    prior_std={"N_Hrrr": 5e8}, reference=model,
                                    measurement_std=STD)
    # stage 1 holds N_Hrrr at 0, stage 2 holds stage 1's values
    assert first.info["held"] == {"N_Hrrr": 0.0}
    assert second.info["held"] == pytest.approx(first.as_dict())
    assert abs(second.rel_error[0]) < 0.3


def test_a_straight_run_excites_nothing_and_is_reported(model):
    straight = run(model, 5, 30.0, rudder=False)
    ekf = identify_ekf(model, straight, ("N_Hr", "C_R4"), measurement_std=STD)
    assert not ekf.identifiable.any(), ekf.reason
    assert all(r.startswith("no excitation") for r in ekf.reason)
    assert np.all(ekf.std > 0.9 * ekf.scale)  # the prior, untouched
    ls = identify_least_squares(model, straight, ("N_Hr", "C_R4"), measurement_std=STD)
    assert not ls.identifiable.any(), ls.reason
    assert all(r.startswith("no excitation") for r in ls.reason)


def test_collinear_parameters_are_reported(model, zigzags):
    # N_Hr and N_Ar both multiply r in still air: only their sum is determined
    ls = identify_least_squares(model, zigzags, ("N_Hr", "N_Ar", "C_R4"), measurement_std=STD)
    assert list(ls.identifiable) == [False, False, True]
    assert "collinear with N_Ar" in ls.reason[0] and "collinear with N_Hr" in ls.reason[1]
    assert np.isinf(ls.std[:2]).all() and math.isinf(ls.condition_number)
    ekf = identify_ekf(model, zigzags[:1], ("N_Hr", "N_Ar"), measurement_std=STD)
    assert not ekf.identifiable.any(), ekf.reason
    assert "collinear with N_Ar" in ekf.reason[0] and "collinear with N_Hr" in ekf.reason[1]


def test_negative_damping_is_flagged(model):
    # a craft whose skirt yaw "damping" N_Hr pushes (the aerodynamic N_Ar keeps it stable)
    pushing = model.with_params(N_Hr=2.0e5)
    data = run(pushing, 15, 60.0, seed=3)
    result = identify_least_squares(pushing, data, ("N_Hr", "Y_Hv"), measurement_std=STD,
                                    scale={"N_Hr": 2e6})
    assert result.estimate[0] > 0
    assert list(result.negative_damping) == [True, False]
    assert "NEGATIVE DAMPING" in result.reason[0] and "NEGATIVE DAMPING" in result.table()
    assert damping_signs(["X_Hu", "X_Huu", "Y_Hv", "N_Hrrr", "N_Hvvr", "C_R4", "Xu", "K_p",
                          "Y_Auv"]) == {"X_Hu": -1.0, "X_Huu": -1.0, "Y_Hv": -1.0,
                                        "N_Hrrr": -1.0, "Xu": -1.0, "K_p": -1.0}


def test_least_squares_recovers_the_truth_on_noise_free_data(model):
    names = LINEAR + ("Y_Hvv", "N_Hrrr", "N_Hvvr")
    clean = [run(model, a, 120.0, noise=np.zeros(4)) for a in (5, 15, 25)]
    ee = identify_least_squares(model, clean, names, reference=model,
                                measurement_std=np.full(4, 1e-6))
    assert np.all(np.abs(ee.rel_error) < 0.01), ee.table()
    # output error from 20 % off, on a short run, two parameters (fast)
    short = run(model, 15, 40.0, noise=np.zeros(4))
    oe = identify_least_squares(model, short, ("N_Hr", "C_R4"), method="output_error",
                                initial={"N_Hr": -2.4e6, "C_R4": 1.6}, reference=model,
                                measurement_std=np.full(4, 1e-3))
    assert np.all(np.abs(oe.rel_error) < 1e-4), oe.table()


def test_fusion_of_segments_counts_the_prior_once():
    rng = np.random.default_rng(0)
    P0, theta0 = np.diag([4.0, 9.0]), np.array([1.0, -2.0])
    J0 = np.linalg.inv(P0)
    # two linear-Gaussian posteriors from the same prior and independent data
    likelihoods = [(rng.normal(size=2), np.diag(rng.uniform(0.5, 2.0, 2))) for _ in range(2)]
    posts = []
    for m, J in likelihoods:
        P = np.linalg.inv(J0 + J)
        posts.append((P @ (J0 @ theta0 + J @ m), P))
    mean, cov = fuse(np.array([p[0] for p in posts]), np.array([p[1] for p in posts]),
                     theta0, P0)
    J_all = J0 + sum(J for _, J in likelihoods)
    expected = np.linalg.solve(J_all, J0 @ theta0 + sum(J @ m for m, J in likelihoods))
    np.testing.assert_allclose(mean, expected, rtol=1e-9)
    np.testing.assert_allclose(cov, np.linalg.inv(J_all), rtol=1e-9)


def test_rts_smoothing_and_noise_estimate(model, zigzags):
    np.testing.assert_allclose(noise_std(zigzags[1]), STD, rtol=0.15)
    data = run(model, 15, 30.0, seed=4)
    result = identify_ekf(model, data, ("C_R4",), measurement_std=STD, smooth=True)
    truth = zigzag(model, math.radians(15), math.radians(15), dt=0.1, duration=30.0).states
    smoothed = result.states[0]
    assert smoothed.shape == truth.shape
    raw = np.std(data.measurements[:, 1] - truth[:, 1])
    assert np.std(smoothed[:, 1] - truth[:, 1]) < 0.5 * raw  # sway speed: better than raw


def test_segment_from_a_recording(zigzags):
    seg = zigzags[0]
    recording = Recording.from_arrays("hovercraft", seg.time, seg.inputs,
                                      dict(zip(CHANNELS, seg.measurements.T, strict=True)))
    again = Segment.from_recording(recording, name="5/5", angular=("psi",))
    assert again.measured == CHANNELS and again.dt == pytest.approx(0.1)
    np.testing.assert_array_equal(again.measurements, seg.measurements)


def test_bad_input_is_named(model, zigzags):
    seg = zigzags[0]
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['N_Hx'\].*known: .*N_Hr"):
        identify_ekf(model, seg, ("N_Hx",))
    with pytest.raises(ValueError, match="more than once"):
        identify_least_squares(model, seg, ("N_Hr", "N_Hr"))
    with pytest.raises(ValueError, match="no parameters"):
        identify_ekf(model, seg, ())
    y = seg.measurements.copy()
    y[7, 2] = np.nan
    with pytest.raises(ValueError, match=r"measurements has 1 non-finite.*\(7, 2\)"):
        Segment(seg.time, seg.inputs, y, CHANNELS)
    with pytest.raises(ValueError, match="5 samples; at least 10"):
        Segment(seg.time[:5], seg.inputs[:5], seg.measurements[:5], CHANNELS)
    with pytest.raises(ValueError, match="inputs has 700 rows but time has 801"):
        Segment(seg.time, seg.inputs[:700], seg.measurements, CHANNELS)
    with pytest.raises(ValueError, match="3 columns but 4 channels"):
        Segment(seg.time, seg.inputs, seg.measurements[:, :3], CHANNELS)
    time = seg.time.copy()
    time[5] += 0.05
    with pytest.raises(ValueError, match="not uniform"):
        Segment(time, seg.inputs, seg.measurements, CHANNELS)
    odd = Segment(seg.time, seg.inputs, seg.measurements, ("u", "v", "r", "phi"))
    with pytest.raises(ValueError, match=r"\['phi'\] are not outputs of model 'hovercraft'"):
        identify_ekf(model, odd, ("N_Hr",))
    with pytest.raises(ValueError, match="prior_std of \\['N_Hv'\\]"):
        identify_ekf(model, seg, ("N_Hv",))  # its value is 0: no default scale
    short = Segment(seg.time[:30], seg.inputs[:30], seg.measurements[:30], CHANNELS)
    with pytest.raises(ValueError, match="too short for the equation-error fit"):
        identify_least_squares(model, short, ("N_Hr",))
    no_sway = Segment(seg.time, seg.inputs, seg.measurements[:, [0, 2, 3]], ("u", "r", "psi"))
    with pytest.raises(ValueError, match="v are not measured"):
        identify_least_squares(model, no_sway, ("N_Hr",))
    with pytest.raises(ValueError, match="method='magic' is invalid"):
        identify_least_squares(model, seg, ("N_Hr",), method="magic")
    with pytest.raises(TypeError, match="Segment"):
        identify_ekf(model, [seg.measurements], ("N_Hr",))
