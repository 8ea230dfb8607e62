"""Tests of marine_envs.sea.waves and .coupling: sea states, realisations, encounter, coupling."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.signal import argrelmax, welch

from marine_envs.blocks import BLOCK
from marine_envs.models import get_model
from marine_envs.sea import (
    Schedule,
    SeaState,
    USVWaveCoupling,
    WaveRealisation,
    encounter_frequency,
    fit_spectrum,
    ndbc_example_path,
    read_ndbc_spectra,
    wave_coupling,
)

G = 9.81
DT = 0.1
HOUR = 36000  # steps of DT
PM1_WP = 1.2561  # one-parameter PM: omega_p = 1.2561 / sqrt(hs)


def _welch(eta, nperseg=2048):
    """Welch estimate of the elevation spectrum in rad/s and m^2 s/rad."""
    f, p = welch(eta, fs=1 / DT, nperseg=nperseg)
    return 2 * math.pi * f, p / (2 * math.pi)


def _smooth(s):
    return np.convolve(s, np.ones(5) / 5, mode="same")


def _eta(sea, n_steps, seed, **kwargs):
    realisation = WaveRealisation(sea, dt=DT, **kwargs)
    return realisation.sample(n_steps, np.random.default_rng(seed))[:, 0]


# --------------------------------------------------------------------------- target spectrum


@pytest.mark.parametrize(
    ("sea", "kind", "wp"),
    [
        (SeaState(hs=2.0, tp=8.0), "pm", 2 * math.pi / 8.0),
        (SeaState(hs=3.0, tp=10.0, spectrum="jonswap", gamma=3.3), "jonswap", 2 * math.pi / 10.0),
        (SeaState(hs=0.3, tp=None), "pm", PM1_WP / math.sqrt(0.3)),
    ],
    ids=["pm", "jonswap", "pm-one-parameter"],
)
def test_hour_reproduces_target_spectrum(sea, kind, wp):
    eta = _eta(sea, HOUR, seed=0, n_components=64)
    assert 4 * eta.std() == pytest.approx(sea.hs, rel=0.05)
    w, s = _welch(eta)
    fit = fit_spectrum(w, s, kind=kind)
    assert 2 * math.pi / fit.tp == pytest.approx(wp, rel=0.05)
    assert w[np.argmax(_smooth(s))] == pytest.approx(wp, rel=0.05)


# --------------------------------------------------------------------------- machinery


def test_blocks_equal_direct_superposition():
    speed, n = 3.0, 64
    realisation = WaveRealisation(SeaState(hs=2.0, tp=8.0), dt=DT, speed=speed, heading=math.pi,
                                  n_components=n)
    steps = 2 * BLOCK + 88
    eta = realisation.sample(steps, np.random.default_rng(42))[:, 0]
    eps = np.random.default_rng(42).uniform(0, 2 * math.pi, n)
    omega_e = realisation.omega + realisation.omega**2 * speed / G  # head seas
    t = np.arange(steps) * DT
    direct = np.cos(np.outer(t, omega_e) + eps) @ realisation._amplitude(None)
    np.testing.assert_allclose(eta, direct, rtol=0, atol=1e-10)


@pytest.mark.parametrize("hs", [0.5, 2.0, 6.0])
def test_component_variance_matches_hs(hs):
    realisation = WaveRealisation(SeaState(hs=hs, tp=8.0), dt=DT, n_components=16)
    variance = np.sum(realisation._amplitude(None) ** 2) / 2
    # the components cover the 0.1 % .. 99.9 % energy band, hence 0.1 % short in Hs
    assert 4 * math.sqrt(variance) == pytest.approx(hs, rel=2e-3)


@pytest.mark.parametrize("sea", [SeaState(hs=2.0, tp=8.0),
                                 SeaState(hs=[(0, 1.0), (30, 1.0), (40, 3.0)], tp=None)],
                         ids=["pm", "pm-shape-follows-hs"])
def test_batch_equals_single_realisations(sea):
    # a boat reset midway starts its blocks at other times than the rest of the batch
    midway, steps = BLOCK + 44, 2 * BLOCK + 200
    batch = WaveRealisation(sea, dt=DT)
    batch.bind(3)
    batch.reset(np.arange(3), [np.random.default_rng(10 + i) for i in range(3)])
    rows = []
    for step in range(steps):
        if step == midway:
            batch.reset(np.array([1]), [np.random.default_rng(99)])
        rows.append(batch.step())
    together = np.stack(rows, axis=1)[..., 0]  # boat x step

    single = WaveRealisation(sea, dt=DT)
    expected = [single.sample(steps, np.random.default_rng(10 + i))[:, 0] for i in range(3)]
    expected[1] = np.concatenate([expected[1][:midway],
                                  single.sample(steps - midway, np.random.default_rng(99))[:, 0]])
    # equal up to rounding: the batch is one matrix product whose shape depends on the batch size
    np.testing.assert_allclose(together, np.stack(expected), rtol=0, atol=1e-12)


def test_same_seed_same_sea_different_seed_different_sea():
    realisation = WaveRealisation(SeaState(hs=2.0, tp=8.0), dt=DT)
    a = realisation.sample(600, np.random.default_rng(5))
    b = realisation.sample(600, np.random.default_rng(5))
    c = realisation.sample(600, np.random.default_rng(6))
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 0.5


# --------------------------------------------------------------------------- schedules


def test_schedule_interpolates_and_holds():
    schedule = Schedule.from_points([(0, 1.0), (600, 3.0)])
    np.testing.assert_allclose(schedule([-50, 0, 150, 300, 600, 5000]),
                               [1.0, 1.0, 1.5, 2.0, 3.0, 3.0])
    assert (schedule.low, schedule.high) == (1.0, 3.0)


@pytest.mark.parametrize(
    ("points", "match"),
    [
        ([(0, 1.0), (0, 2.0)], "increasing"),
        ([(10, 1.0), (5, 2.0)], "increasing"),
        ([(0, 1.0), (10, 0.0)], "> 0"),
        ([(0, -1.0)], "> 0"),
    ],
)
def test_schedule_rejects_invalid_points(points, match):
    with pytest.raises(ValueError, match=match):
        Schedule.from_points(points)


def test_schedule_rejects_empty():
    with pytest.raises(ValueError, match="non-empty"):
        Schedule((), ())
    with pytest.raises(ValueError):
        Schedule.from_points([])


STEP_HS = [(0, 1.0), (1000, 1.0), (1001, 3.0), (3000, 3.0)]
PLATEAUS = [(slice(1000, 9000), 1.0), (slice(12000, 29000), 3.0)]  # steps well inside each


def test_varying_hs_follows_schedule():
    eta = _eta(SeaState(hs=STEP_HS, tp=8.0), 30000, seed=1)
    for window, hs in PLATEAUS:
        assert 4 * eta[window].std() == pytest.approx(hs, rel=0.1)


def test_varying_hs_scales_constant_realisation():
    """With a fixed shape, a schedule only scales the unit-Hs realisation by hs(t)."""
    schedule = Schedule.from_points([(0, 1.0), (40, 3.0)])
    steps = 2 * BLOCK + 50
    varying = _eta(SeaState(hs=schedule, tp=8.0), steps, seed=2)
    unit = _eta(SeaState(hs=1.0, tp=8.0), steps, seed=2)
    np.testing.assert_allclose(varying, unit * schedule(np.arange(steps) * DT), atol=1e-12)


def test_one_parameter_pm_shape_follows_hs():
    eta = _eta(SeaState(hs=STEP_HS, tp=None), 30000, seed=3)
    peaks = []
    for window, hs in PLATEAUS:
        assert 4 * eta[window].std() == pytest.approx(hs, rel=0.1)
        w, s = _welch(eta[window], nperseg=1024)
        peaks.append(2 * math.pi / fit_spectrum(w, s, kind="pm").tp)
        assert peaks[-1] == pytest.approx(PM1_WP / math.sqrt(hs), rel=0.1)
    assert peaks[0] / peaks[1] == pytest.approx(math.sqrt(3), rel=0.1)


# --------------------------------------------------------------------------- encounter


def test_encounter_frequency_by_heading():
    omega, speed = np.array([0.3, 0.6, 1.0]), 5.0
    shift = omega**2 * speed / G
    np.testing.assert_allclose(encounter_frequency(omega, speed, math.pi), omega + shift)
    np.testing.assert_allclose(encounter_frequency(omega, speed, 0.0), omega - shift)
    np.testing.assert_allclose(encounter_frequency(omega, speed, math.pi / 2), omega)
    np.testing.assert_array_equal(encounter_frequency(omega, 0.0, 1.0), omega)
    # docs/models.md 2.5: beta = 120 deg, U = 6.08 m/s
    np.testing.assert_allclose(encounter_frequency(omega, 6.08, math.radians(120)),
                               omega + 0.3099 * omega**2, rtol=1e-4)


def test_realisation_peaks_at_encounter_frequency():
    sea, speed, wp = SeaState(hs=3.0, tp=10.0, spectrum="jonswap"), 6.0, 2 * math.pi / 10.0
    eta = _eta(sea, HOUR, seed=4, speed=speed, heading=math.pi)
    w, s = _welch(eta)
    peak = w[np.argmax(_smooth(s))]
    we = float(encounter_frequency(wp, speed, math.pi))
    assert we > 1.3 * wp
    assert peak == pytest.approx(we, rel=0.05)
    assert 4 * eta.std() == pytest.approx(3.0, rel=0.05)  # moving does not change the energy


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"hs": 0.0}, "hs="),
        ({"hs": -1.0}, "hs="),
        ({"hs": math.nan}, "hs="),
        ({"tp": 0.0}, "tp="),
        ({"tp": -8.0}, "tp="),
        ({"spectrum": "bretschneider"}, "spectrum="),
        ({"hs": None}, "hs=None"),
        ({"spectrum": "jonswap", "tp": None}, "tp=None"),
    ],
)
def test_sea_state_rejects_invalid(kwargs, match):
    with pytest.raises(ValueError, match=match):
        SeaState(**kwargs)


@pytest.mark.parametrize(
    "kwargs",
    [{"n_components": 0}, {"n_components": 8.0}, {"dt": 0.0}, {"dt": -0.1}, {"speed": -1.0}],
)
def test_realisation_rejects_invalid(kwargs):
    options = {"dt": DT, **kwargs}
    name = next(iter(kwargs))
    with pytest.raises(ValueError, match=f"{name}="):
        WaveRealisation(SeaState(), **options)


# --------------------------------------------------------------------------- measured spectrum


@pytest.fixture(scope="module")
def measured():
    return read_ndbc_spectra(ndbc_example_path()).spectrum(0)


def test_measured_spectrum_drives_realisation(measured):
    eta = _eta(SeaState(hs=None, spectrum=measured, tp=None), HOUR, seed=5)
    assert 4 * eta.std() == pytest.approx(measured.hs, rel=0.05)
    w, s = _welch(eta)
    smooth = _smooth(s)
    local = argrelmax(smooth, order=5)[0]
    maxima = w[local[smooth[local] > 0.05 * smooth.max()]]
    swell, wind_sea = 2 * math.pi * 0.06, 2 * math.pi * 0.17
    for peak in (swell, wind_sea):
        assert np.min(np.abs(maxima / peak - 1)) < 0.15, (peak, maxima)
    between = (w > swell * 1.3) & (w < wind_sea * 0.85)
    assert smooth[between].min() < 0.7 * smooth[np.abs(w / wind_sea - 1) < 0.15].max()


def test_measured_spectrum_rescaled(measured):
    eta = _eta(SeaState(hs=2.0, spectrum=measured, tp=None), HOUR, seed=6)
    assert measured.hs > 3.0  # so that the rescaling is a real change
    assert 4 * eta.std() == pytest.approx(2.0, rel=0.05)


# --------------------------------------------------------------------------- USV coupling

OMEGA = np.linspace(0.2, 3.0, 50)
K = OMEGA**2 / G


def _response(heading, **params):
    return wave_coupling(get_model("usv", **params), heading)(OMEGA)


def test_beam_seas_roll_only():
    model = get_model("usv")
    response = _response(math.pi / 2)
    roll = model.params.wn**2 * K * np.exp(-K * 3.0)
    assert np.abs(response[:, 0]).max() < 1e-12 * np.abs(response[:, 1]).max()
    np.testing.assert_allclose(response[:, 1], -1j * roll, rtol=1e-12)  # slope: 90 deg lag
    for heading in np.linspace(0, math.pi, 13):
        assert np.all(np.abs(_response(heading)[:, 1]) <= np.abs(response[:, 1]) * (1 + 1e-12))


@pytest.mark.parametrize("heading", [0.0, math.pi], ids=["following", "head"])
def test_head_and_following_seas_no_roll(heading):
    beam = np.abs(_response(math.pi / 2)[:, 1]).max()
    assert np.abs(_response(heading)[:, 1]).max() < 1e-12 * beam


def test_quartering_seas_yaw():
    params = get_model("usv").params
    yaw = abs(params.Kdr / params.Tr) * 10.0 * K * np.exp(-K * 3.0)
    np.testing.assert_allclose(np.abs(_response(math.pi / 4)[:, 0]), yaw, rtol=1e-12)
    np.testing.assert_allclose(np.abs(_response(3 * math.pi / 4)[:, 0]), yaw, rtol=1e-12)


def test_roll_coupling_scales_with_wn_squared():
    slow, fast = _response(math.pi / 3, wn=0.5), _response(math.pi / 3, wn=1.0)
    np.testing.assert_allclose(fast[:, 1], 4 * slow[:, 1], rtol=1e-12)
    np.testing.assert_allclose(fast[:, 0], slow[:, 0], rtol=1e-12)


def test_short_waves_attenuated():
    omega = np.array([0.5, 3.0])
    k = omega**2 / G
    coupling = USVWaveCoupling(heading=math.pi / 3, draft=3.0)
    per_slope = np.abs(coupling(omega, get_model("usv"))) / k[:, None]
    ratio = per_slope[1] / per_slope[0]
    np.testing.assert_allclose(ratio, math.exp(-(k[1] - k[0]) * 3.0), rtol=1e-12)
    assert np.all(ratio < 0.1)


def test_coupling_unknown_model():
    with pytest.raises(ValueError, match="rov"):
        wave_coupling(SimpleNamespace(name="rov"), math.pi / 2)


def test_coupled_realisation_channels():
    model = get_model("usv")
    realisation = WaveRealisation(SeaState(hs=2.0, tp=8.0), wave_coupling(model, math.pi / 2),
                                  dt=DT)
    d = realisation.sample(2 * BLOCK, np.random.default_rng(7))
    assert d.shape == (2 * BLOCK, 2)
    assert np.abs(d[:, 0]).max() < 1e-12 * np.abs(d[:, 1]).max()
    assert np.abs(d[:, 1]).max() > 1e-3
