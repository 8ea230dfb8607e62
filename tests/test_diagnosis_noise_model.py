"""The diagnosis's noise model: the sea as coloured forcing, and the tests that keep a chance
fluctuation from becoming a finding."""


import numpy as np
import pytest
from scipy import signal

from agents.simulate import simulate
from estimators.diagnosis import diagnose
from estimators.diagnosis.cases import PARTIAL, Case, build_effect, run_case
from estimators.diagnosis.hypotheses import (
    _in_both_halves,
    _near,
    _ringing_modes,
    _targets,
    spectral_peak,
)
from estimators.diagnosis.residuals import (
    AugmentedDynamics,
    Forcing,
    Sea,
    denoised,
    estimate,
    model_noise_spread,
)
from estimators.diagnosis.synthetic import SEA, synthesize, typical_effect
from marine_envs.models import get_model
from marine_envs.models.effects import Effect, EffectModel
from marine_envs.sea.coupling import USVWaveCoupling


def _forcing(residuals, state):
    """The forcing in ``state``'s equation: its own or an environment channel's."""
    i = residuals.model.state_names.index(state)
    return next(f for f in residuals.forcing if i in f.equations)


def _environment(residuals):
    model = residuals.model
    return {model.disturbance_names[f.disturbance]: f for f in residuals.forcing
            if f.disturbance is not None}


def test_the_sea_is_modelled_with_its_own_correlation_time():
    model = get_model("usv")
    residuals = estimate(synthesize(model, seed=102, noise=0.05), model)
    true_tau = SEA["usv"][1]  # the generator's wave moments: Gauss-Markov, 2 s
    assert _forcing(residuals, "r").tau == pytest.approx(true_tau, rel=0.5)
    # the wave moments are added to the equations: each measured one keeps a forcing of its own
    assert not _environment(residuals)
    assert {model.state_names[f.state] for f in residuals.forcing} == {"r", "p"}


@pytest.fixture(scope="module")
def usv_seaway():
    """An effect-free 300-s USV-v0 record: its default sea (Hs 2 m, Tp 8 s, 60 deg) and
    sensors, LQR with the generator's dither."""
    return simulate("marine_envs/USV-v0", 3000, seed=100, policy="lqr", amplitude=0.15)


def test_the_usv_s_sea_is_one_narrow_band_process_in_both_moments(usv_seaway):
    # the environment's yaw moment is a fixed multiple of its roll moment, peaking beside the
    # 0.63 rad/s roll mode
    model = get_model("usv")
    residuals = estimate(usv_seaway, model)
    sea = residuals.sea
    assert sea is not None and not residuals.forcing  # no equation keeps a forcing of its own
    assert sea.omega == pytest.approx(0.6, abs=0.05) and sea.zeta < 0.2  # narrow band
    (r, a_r, c_r), (p, a_p, c_p) = sea.loading
    assert (model.state_names[r], model.state_names[p]) == ("r", "p")
    # the coupling's ratio (both moments follow the wave slope): 0.32 at 60 deg
    k = model.params
    ratio = abs(k.Kdr / k.Tr) * USVWaveCoupling(0.0).yaw_gain * 2 * np.cos(np.radians(60)) \
        / k.wn**2
    assert np.hypot(a_r, c_r) / np.hypot(a_p, c_p) == pytest.approx(ratio, rel=0.25)


def test_a_narrow_band_sea_at_the_roll_resonance_is_taken_for_no_term(usv_seaway):
    # with an independent first-order forcing per equation this record got a negative linear
    # roll damping (108 % of the model's) and a roll-to-yaw coupling, both at confidence 1.00
    diagnosis = diagnose(usv_seaway, "usv")
    assert not [f for f in diagnosis.findings if f.confidence >= 0.5], diagnosis.findings


def test_a_slow_current_is_the_environment_not_a_finding():
    # the ROV's current is a 60-s Gauss-Markov process; fitted to the equation errors (where
    # the thrust that holds against it removes it) its time scale came out as 2-3 s, and this
    # effect-free record got a confident constant force on u
    rov = get_model("rov")
    recording = synthesize(rov, seed=100, noise=0.05)
    current = _environment(estimate(recording, rov))
    assert set(current) == {"current_n", "current_e", "current_d"}  # not the morph command
    assert all(f.tau > 15.0 for f in current.values())
    diagnosis = diagnose(recording, rov)
    assert not [f for f in diagnosis.findings if f.confidence >= 0.5], diagnosis.findings
    noise_model = diagnosis.to_dict()["noise_model"]
    assert {"disturbance": "current_n", "unit": "m/s"}.items() <= noise_model[-3].items()


def test_a_steady_wind_is_estimated_with_the_environment():
    # the hovercraft environment's 5 m/s wind from the north-east, under a dithered LQR: the
    # filter carries the mean wind as constant states (zero-mean gusts alone left it to the
    # findings: a sensor bias on v, a constant surge force)
    recording = simulate("marine_envs/Hovercraft-v0", 3000, seed=7, policy="lqr",
                         amplitude=0.15)
    wind = _environment(estimate(recording, get_model("hovercraft")))
    truth = -5.0 * np.cos(np.radians(45.0))  # blowing to the south-west: both components < 0
    assert wind["wind_north"].level == pytest.approx(truth, abs=0.5)
    assert wind["wind_east"].level == pytest.approx(truth, abs=0.5)


def test_a_missing_term_stays_a_model_error_not_forcing():
    model = get_model("usv")
    effect = typical_effect("usv", "quadratic_damping", "r", strength=0.5)
    residuals = estimate(synthesize(model, [effect], seed=1, noise=0.0, sea=0.0), model)
    error_variance = np.var(residuals.error[:, model.state_names.index("r")])
    assert _forcing(residuals, "r").variance < 0.1 * error_variance


def test_a_wave_must_persist_through_the_record():
    rng = np.random.default_rng(4)
    t = np.arange(3000) * 0.1
    line = np.sin(1.2 * t)
    noise = rng.standard_normal(t.size)
    assert _in_both_halves(noise + line, 1.2, 0.1, 1e-4)
    assert not _in_both_halves(noise + np.where(t < 150, line, 0.0), 1.2, 0.1, 1e-4)
    assert not _in_both_halves(noise, 1.2, 0.1, 1e-4)


def test_only_an_oscillatory_mode_explains_a_spectral_peak_away():
    def rings(model: str, omega: float) -> bool:
        return bool(_near(omega, _ringing_modes(get_model(model)), resolution=0.1))

    assert rings("usv", 0.63)  # its roll mode (zeta 0.09): the sea rings it in every record
    assert rings("rov", 5.66)  # a lightly damped mode
    assert not rings("rov", 1.0)  # its unstable real pole at 1.01 1/s rings at no frequency
    assert not rings("usv", 2.0)


def test_a_line_is_looked_for_beside_the_modes_the_sea_rings():
    rng = np.random.default_rng(1)
    dt, t = 0.1, np.arange(6000) * 0.1
    mode = signal.lfilter([0.01], [1.0, -2 * 0.995 * np.cos(0.6 * dt), 0.995**2],
                          rng.standard_normal(t.size))  # zeta 0.08: a roll mode the sea rings
    white = rng.standard_normal(t.size) + mode
    line = 0.3 * np.sin(1.0 * t)
    assert spectral_peak(white + line, dt)["omega"] == pytest.approx(0.6, abs=0.05)
    beside = spectral_peak(white + line, dt, beside=[(0.6, 0.083)])
    assert beside["omega"] == pytest.approx(1.0, abs=0.05) and beside["p_value"] < 1e-4
    # nor is the mode's skirt a line
    assert spectral_peak(white, dt, beside=[(0.6, 0.083)])["p_value"] > 1e-3


def test_a_roll_wave_forcing_is_found_without_the_roll_rate():
    # the unmeasured roll rate's equation error is the smoother's, and its roll mode hid the line
    effect = build_effect("usv", ("wave_frequency", "p", {}), seed=1)
    outcome = run_case(Case("usv", (effect,), noise=0.05, seed=1, measured=PARTIAL["usv"]))
    assert outcome.ranked_right and outcome.parameter_ok, outcome


def test_a_heave_wave_forcing_on_the_rov_is_found():
    # every ROV wave case (1 rad/s, on w) went unseen while its real pole counted as a mode
    effect = typical_effect("rov", "wave_frequency", "w", seed=0)
    diagnosis = diagnose(synthesize("rov", [effect], seed=0, noise=0.05), "rov")
    assert (diagnosis.findings[0].effect, diagnosis.findings[0].target) == ("wave_frequency", "w")
    assert diagnosis.findings[0].parameters["omega"] == pytest.approx(1.0, abs=0.1)


def test_a_model_s_own_sea_keeps_its_stated_noise_and_is_no_target():
    dp = get_model("dp_vessel")
    residuals = estimate(synthesize(dp, seed=3, noise=0.05, duration=200.0), dp)
    targets = {dp.state_names[i] for i in _targets(residuals)}
    assert targets.isdisjoint(dp.noise_model_states) and "u" in targets
    spread = model_noise_spread(dp, ("north", "east", "psi"), 0.1, 30)
    assert np.all(np.diff(spread, axis=0) >= 0) and np.all(spread[-1] > 0)  # grows with horizon
    assert not np.any(model_noise_spread(get_model("usv"), ("r", "psi"), 0.1, 30))


def test_the_dp_vessel_s_missing_drag_is_found_through_its_own_sea():
    # before its bias and wave-frequency states kept their stated noise, none of 14 DP cases
    # was ranked right: the EKF let the bias absorb every slow model error
    effect = build_effect("dp_vessel", ("quadratic_damping", "u", {}), seed=5)
    outcome = run_case(Case("dp_vessel", (effect,), noise=0.05, seed=5))
    assert outcome.ranked_right, outcome
    assert outcome.parameter_ok


def test_the_sea_share_is_reported_when_the_model_carries_a_sea():
    dp = get_model("dp_vessel")
    effect = build_effect("dp_vessel", ("linear_damping", "v", {}), seed=6)
    diagnosis = diagnose(synthesize(dp, [effect], seed=6, noise=0.05), dp)
    assert 0.0 < diagnosis.fit["expected_from_sea"] <= 1.0


def test_an_environment_the_measurements_cannot_determine_forces_each_equation():
    hydrofoil = get_model("hydrofoil")  # six sea channels, two force equations
    residuals = estimate(synthesize(hydrofoil, seed=3, noise=0.05, duration=100.0), hydrofoil)
    assert not _environment(residuals)
    assert {hydrofoil.state_names[f.state] for f in residuals.forcing} == {"xi_dot", "theta_dot"}


def test_a_recorded_wind_is_an_input_not_an_estimated_environment():
    # an anemometer's wind (5 % noise): the diagnosis takes it as a known input, so the filter
    # carries no wind state and the finding explains more of the held-out error than with the
    # wind estimated (58 % on this record)
    effect = typical_effect("hovercraft", "linear_damping", "v", seed=0)
    recording = synthesize("hovercraft", [effect], seed=0, noise=0.05,
                           disturbances=("wind_north", "wind_east"))
    assert recording.disturbance_names == ("wind_north", "wind_east")
    diagnosis = diagnose(recording, "hovercraft")
    assert [(f.effect, f.target) for f in diagnosis.findings] == [("linear_damping", "v")]
    assert diagnosis.findings[0].parameters["c"] == pytest.approx(effect.parameters["c"],
                                                                  rel=0.3)
    assert diagnosis.fit["improvement"] > 0.8
    report = diagnosis.to_dict()
    assert report["measured_disturbances"] == ["wind_north", "wind_east"]
    assert not [f for f in report.get("noise_model", []) if "disturbance" in f]
    assert "taken as known inputs: wind_north, wind_east" in diagnosis.summary()


def test_the_rov_s_recorded_morph_command_lets_the_model_follow_a_morphing_record():
    # the ROV environment morphs at mid-record; without its command the model cannot follow
    # (predictions 4.4x worse than holding the last sample); with it, the hidden current is
    # found
    effect = typical_effect("rov", "current", "w", seed=0)
    recording = simulate("marine_envs/ROV-v0", 3000, seed=0, policy="lqr", amplitude=0.15,
                         env_kwargs={"effects": [effect]}, disturbances=("s_cmd",))
    assert np.ptp(recording.data["s_cmd"]) == 1.0  # the morph happened
    outcome = run_case(Case("rov", (effect,), 0.0, 0, 300.0), recording)
    assert outcome.ranked_right, outcome


def test_a_measured_disturbance_is_cleared_of_its_sensor_noise():
    # a 60-s Gauss-Markov current (0.05 m/s) read by a profiler with 0.02 m/s of white noise:
    # taken as it is, the noise would drive the model as a real current
    rng = np.random.default_rng(4)
    dt, n = 0.1, 3000
    current = np.zeros(n)
    for k in range(1, n):
        current[k] = current[k - 1] * (1 - dt / 60) + 0.05 * np.sqrt(2 * dt / 60) * rng.normal()
    read = current + 0.02 * rng.standard_normal(n)
    cleared = denoised(np.c_[read, current])
    assert np.std(cleared[:, 0] - current) < 0.4 * np.std(read - current)
    assert np.std(cleared[:, 1] - current) < 0.1 * np.std(current)  # a clean one is kept


def _augmented(model, sea=None):
    """The filter's dynamics with an own forcing on two equations and both wind channels,
    the first with a steady part (and a ``sea``)."""
    own = [Forcing(0, 2.0, 0.1), Forcing(2, 5.0, 0.2)]
    environment = [Forcing(None, 30.0, 1.0, 0, (0, 1), 4.0), Forcing(None, 20.0, 1.0, 1, (0, 1))]
    return AugmentedDynamics(model, own, environment, sea)


def test_compiled_filter_dynamics_with_a_sea_equal_their_numpy_reference():
    rng = np.random.default_rng(7)
    model = get_model("hovercraft")
    sea = Sea(0.6, 0.1, ((1, 0.1, 0.02), (4, 0.05, -0.01)))
    f = _augmented(model, sea)
    assert f._kernel is not None
    z = rng.normal(size=(9, f.width)) * np.concatenate([np.abs(model.x0) + 1.0,
                                                        np.ones(f.width - 6)])
    u = model.u0 + rng.normal(size=(9, len(model.input_names)))
    got, want = f(z, u, np.zeros((9, 0))), f.reference(z, u)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    waves = z[:, 10:12]  # after the four Gauss-Markov states: the sea drives its equations
    np.testing.assert_allclose(want[:, 10:12], waves @ sea.dynamics().T)
    without = _augmented(model).reference(np.delete(z, [10, 11], axis=1), u)
    np.testing.assert_allclose(want[:, :6] - without[:, :6], waves @ sea.gains(6).T,
                               atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("forcing", [True, False])
def test_compiled_filter_dynamics_equal_their_numpy_reference(forcing):
    rng = np.random.default_rng(5)
    model = get_model("hovercraft")
    f = _augmented(model) if forcing else AugmentedDynamics(model, [], [])
    assert f._kernel is not None  # the compiled path is the one tested
    z = rng.normal(size=(9, f.width)) * np.concatenate([np.abs(model.x0) + 1.0,
                                                        np.ones(f.width - 6)])
    u = model.u0 + rng.normal(size=(9, len(model.input_names)))
    got, want = f(z, u, np.zeros((9, 0))), f.reference(z, u)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    if forcing:  # the forcings reach their equations and decay; the steady part is constant
        assert np.all(want[:, 6:10] == -z[:, 6:10] / f.tau) and not want[:, 10].any()
    else:
        np.testing.assert_array_equal(want, model.rhs(z, u))


def test_filter_dynamics_of_a_model_without_compiled_equations_take_the_numpy_path():
    rng = np.random.default_rng(6)
    model = EffectModel(get_model("hovercraft"), [Effect("current", "r", {"b": 0.01})])
    f = _augmented(model)
    assert f._kernel is None
    z, u = rng.normal(size=(4, f.width)), rng.normal(size=(4, len(model.input_names)))
    np.testing.assert_array_equal(f(z, u, np.zeros((4, 0))), f.reference(z, u))
