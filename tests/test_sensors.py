"""Tests of marine_envs.sensors: quantizers, noise, delay, dropout, wrapping and the suite."""

import math

import numpy as np
import pytest

from marine_envs.blocks import BLOCK
from marine_envs.sensors import (
    Bias,
    Delay,
    Dropout,
    GaussianNoise,
    Quantizer,
    SampleHold,
    SensorSuite,
    WrapAngle,
    ZoomingQuantizer,
    per_channel,
    quantize,
)

ONE = np.array([0])


def _bound(stage, batch_size=1, seeds=None):
    """Bind ``stage`` to ``batch_size`` boats and reset them all with seeded generators."""
    stage.bind(batch_size)
    seeds = range(batch_size) if seeds is None else seeds
    stage.reset(np.arange(batch_size), [np.random.default_rng(s) for s in seeds])
    return stage


def _run(stage, z):
    """Feed the rows of ``z`` (steps x channels) to a one-boat stage; outputs (steps x channels)."""
    return np.concatenate([stage(row[None, :].copy()) for row in z])


# --------------------------------------------------------------------------- static quantizer


def test_quantize_error_within_half_step():
    rng = np.random.default_rng(1)
    mu = np.array([0.01, 0.5, 3.0])
    z = rng.uniform(-50, 50, (5000, 3))
    q = quantize(z, mu)
    assert np.all(np.abs(q - z) <= mu / 2 * (1 + 1e-12))
    multiples = q / mu
    np.testing.assert_allclose(multiples, np.rint(multiples), rtol=0, atol=1e-6)


def test_quantizer_nan_step_passes_channel_through():
    rng = np.random.default_rng(2)
    z = rng.normal(0, 10, (200, 3))
    out = Quantizer([math.nan, 0.25, 2.0])(z.copy())
    np.testing.assert_array_equal(out[:, 0], z[:, 0])
    np.testing.assert_array_equal(out[:, 1:], quantize(z[:, 1:], np.array([0.25, 2.0])))
    assert np.all(np.abs(out - z) <= np.array([0.0, 0.125, 1.0]) * (1 + 1e-12))


def test_quantizer_noncontiguous_channels():
    rng = np.random.default_rng(2)
    z = rng.normal(0, 10, (200, 3))
    out = Quantizer([0.25, math.nan, 2.0])(z.copy())
    np.testing.assert_array_equal(out[:, 1], z[:, 1])
    np.testing.assert_array_equal(out[:, [0, 2]], quantize(z[:, [0, 2]], np.array([0.25, 2.0])))


@pytest.mark.parametrize("step", [0.0, -0.1, math.inf])
def test_quantizer_rejects_bad_step(step):
    with pytest.raises(ValueError, match="quantization"):
        Quantizer([0.1, step])


# --------------------------------------------------------------------------- zooming quantizer


def test_zooming_relative_error_bound_and_mu():
    rng = np.random.default_rng(3)
    k, groups = 0.6, [[0], [1, 2]]
    zq = _bound(ZoomingQuantizer(groups, k=k), batch_size=500)
    z = rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-4, 4, (500, 1))
    q = zq(z.copy())
    for g, group in enumerate(groups):
        norm = np.linalg.norm(z[:, group], axis=1)
        error = np.linalg.norm(q[:, group] - z[:, group], axis=1)
        assert np.all(error <= k * norm * (1 + 1e-12))
        np.testing.assert_allclose(zq.mu[:, g], 2 * k * norm / math.sqrt(len(group)), rtol=1e-12)
    # the bound is not trivially met by q = z: the quantizer does coarsen the signal
    assert np.mean(q != z) > 0.5


def test_zooming_relative_zero_gives_zero():
    zq = _bound(ZoomingQuantizer([[0], [1, 2]]), batch_size=2)
    z = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    with np.errstate(all="raise"):
        q = zq(z.copy())
    np.testing.assert_array_equal(q[0], 0.0)
    np.testing.assert_array_equal(zq.mu[0], 0.0)
    np.testing.assert_array_equal(q[1, 1:], 0.0)


@pytest.mark.parametrize("k", [0.0, 1.0, -0.5, 1.5])
def test_zooming_rejects_k_outside_unit_interval(k):
    with pytest.raises(ValueError, match="k="):
        ZoomingQuantizer([[0]], k=k)


def test_zoom_law_zooms_in_then_out_on_saturation():
    levels, zoom_in = 16, 0.8
    zq = _bound(ZoomingQuantizer([[0]], law="zoom", mu0=1.0, levels=levels, zoom_in=zoom_in))
    mus = []
    for step in range(150):
        z = 5.0 * 0.9**step
        mu = zq.mu[0, 0]
        q = zq(np.array([[z]]))[0, 0]
        assert abs(round(z / mu)) <= levels  # a decaying signal never saturates
        assert abs(q - z) <= mu / 2 * (1 + 1e-12)
        mus.append(mu)
    assert np.all(np.diff(mus) <= 0)
    assert mus[-1] < 1e-4  # the zoom followed the signal down (0.9^150 ~ 1e-7)

    mu = zq.mu[0, 0]
    q = zq(np.array([[1.0]]))[0, 0]  # a sudden large value saturates the quantizer
    assert q == pytest.approx(levels * mu)
    assert zq.mu[0, 0] == pytest.approx(mu / zoom_in)
    for _ in range(100):  # held, it is zoomed out to until representable again
        mu = zq.mu[0, 0]
        q = zq(np.array([[1.0]]))[0, 0]
        if abs(round(1.0 / mu)) <= levels:
            break
    assert abs(q - 1.0) <= mu / 2


# --------------------------------------------------------------------------- Gaussian noise


def test_noise_standard_deviation_per_channel():
    std = np.array([0.1, 2.0, 0.0, 5.0])
    noise = _bound(GaussianNoise(std), seeds=[4])
    z = np.tile([1.0, -2.0, 3.0, 0.5], (20000, 1))
    out = _run(noise, z)
    np.testing.assert_array_equal(out[:, 2], 3.0)
    np.testing.assert_allclose(out.std(axis=0)[[0, 1, 3]], std[[0, 1, 3]], rtol=0.03)
    np.testing.assert_allclose(out.mean(axis=0)[[0, 1, 3]], z[0, [0, 1, 3]], atol=0.1)


def test_noise_same_seed_same_noise():
    z = np.zeros((600, 2))
    a = _run(_bound(GaussianNoise([1.0, 0.5]), seeds=[5]), z)
    b = _run(_bound(GaussianNoise([1.0, 0.5]), seeds=[5]), z)
    c = _run(_bound(GaussianNoise([1.0, 0.5]), seeds=[6]), z)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def _noisy_suite():
    return SensorSuite.standard(("r", "psi", "phi"), noise_std={"r": 0.01, "psi": 0.1, "phi": 0.2},
                                dropout={"psi": 0.3})


def test_batch_equals_single_boats_with_midway_reset():
    steps, midway = 2 * BLOCK + 200, BLOCK + 44
    assert midway > BLOCK and steps - midway > BLOCK  # crosses block boundaries on both sides
    rng = np.random.default_rng(7)
    truth = rng.normal(size=(steps, 3, 3))  # step x boat x channel

    batch = _noisy_suite()
    batch.bind(3)
    batch.reset(np.arange(3), [np.random.default_rng(10 + i) for i in range(3)])
    singles = [_noisy_suite() for _ in range(3)]
    for i, single in enumerate(singles):
        single.bind(1)
        single.reset(ONE, [np.random.default_rng(10 + i)])

    for step in range(steps):
        if step == midway:
            batch.reset(np.array([1]), [np.random.default_rng(99)])
            singles[1].reset(ONE, [np.random.default_rng(99)])
        measured = batch.measure(truth[step].copy())
        valid = batch.valid.copy()
        for i, single in enumerate(singles):
            alone = single.measure(truth[step, i][None].copy())
            np.testing.assert_array_equal(measured[i], alone[0])
            np.testing.assert_array_equal(valid[i], single.valid[0])
    assert not np.array_equal(measured[0], truth[-1, 0])  # the noise was there


# --------------------------------------------------------------------------- delay


def test_delay_per_channel_and_after_reset():
    lags = np.array([0, 2, 5])
    delay = _bound(Delay(lags))
    for start in (0.0, 1000.0):  # first episode, then a new one after a reset
        delay.reset(ONE, [np.random.default_rng(0)])
        z = start + np.arange(1, 21, dtype=float)[:, None] * np.array([1.0, 10.0, 100.0])
        out = _run(delay, z)
        for c, lag in enumerate(lags):
            expected = z[np.maximum(np.arange(20) - lag, 0), c]
            np.testing.assert_array_equal(out[:, c], expected)


@pytest.mark.parametrize("lags", [[-1, 0], [1.5, 0]])
def test_delay_rejects_negative_or_fractional(lags):
    with pytest.raises(ValueError, match="delay"):
        Delay(lags)


# --------------------------------------------------------------------------- dropout


def test_dropout_rate_hold_and_valid():
    prob = np.array([0.1, 0.5, 0.0])
    dropout = _bound(Dropout(prob), seeds=[8])
    z = np.arange(20000, dtype=float)[:, None] * np.ones(3)
    valid = np.empty(z.shape, dtype=bool)
    out = np.empty(z.shape)
    for step, row in enumerate(z):
        out[step] = dropout(row[None].copy())[0]
        valid[step] = dropout.valid[0]
    np.testing.assert_allclose(1 - valid.mean(axis=0), prob, atol=0.015)
    np.testing.assert_array_equal(out[valid], z[valid])  # fresh samples pass through
    held = ~valid[1:]
    np.testing.assert_array_equal(out[1:][held], out[:-1][held])  # lost ones hold the last value


def test_dropout_first_sample_after_reset_is_valid():
    dropout = _bound(Dropout([0.99, 0.99]), batch_size=2, seeds=[9, 10])
    for episode in range(30):
        dropout.reset(np.array([0]), [np.random.default_rng(100 + episode)])
        out = dropout(np.full((2, 2), float(episode)))
        assert dropout.valid[0].all()
        np.testing.assert_array_equal(out[0], float(episode))


def test_sample_hold_samples_each_channel_at_its_rate_and_marks_fresh_samples():
    hold = _bound(SampleHold([1, 3]), batch_size=2)
    z = np.arange(8, dtype=float)[:, None] * np.ones(2)
    out = []
    for k, row in enumerate(z):
        if k == 2:  # boat 1 starts a new episode: its slow channel samples at once
            hold.reset(np.array([1]), [np.random.default_rng(0)])
        out.append(hold(np.stack([row, row])))
        assert hold.valid[0, 1] == (k % 3 == 0)
    out = np.array(out)
    np.testing.assert_array_equal(out[:, 0, 0], z[:, 0])
    np.testing.assert_array_equal(out[:, 0, 1], [0, 0, 0, 3, 3, 3, 6, 6])
    np.testing.assert_array_equal(out[:, 1, 1], [0, 0, 2, 2, 2, 5, 5, 5])
    with pytest.raises(ValueError, match="sample_period"):
        SampleHold([1, 0.5])


def test_suite_mask_combines_slow_sensors_and_dropout():
    suite = SensorSuite.standard(("a", "b"), sample_period={"a": 2}, dropout={"b": 0.5})
    suite.bind(1)
    suite.reset(np.array([0]), [np.random.default_rng(3)])
    masks = []
    for _ in range(400):
        suite.measure(np.zeros((1, 2)))
        masks.append(suite.valid[0].copy())
    masks = np.array(masks)
    assert masks[:, 0].mean() == pytest.approx(0.5) and 0.4 < masks[:, 1].mean() < 0.6


@pytest.mark.parametrize("prob", [1.0, 1.5, -0.1])
def test_dropout_rejects_bad_probability(prob):
    with pytest.raises(ValueError, match="dropout"):
        Dropout([0.1, prob])


# --------------------------------------------------------------------------- wrapping


def test_wrap_selected_channels_only():
    suite = SensorSuite.standard(("r", "psi"), wrap=("psi",))
    assert [type(s) for s in suite.stages] == [WrapAngle]
    suite.bind(1000)
    rng = np.random.default_rng(11)
    z = rng.uniform(-30, 30, (1000, 2))
    z[:4, 1] = [math.pi, -math.pi, 3 * math.pi, 0.0]
    out = suite.measure(z.copy())
    np.testing.assert_array_equal(out[:, 0], z[:, 0])
    assert np.all((out[:, 1] > -math.pi) & (out[:, 1] <= math.pi))
    turns = (z[:, 1] - out[:, 1]) / (2 * math.pi)
    np.testing.assert_allclose(turns, np.rint(turns), rtol=0, atol=1e-12)
    np.testing.assert_allclose(out[:4, 1], [math.pi, math.pi, math.pi, 0.0], atol=1e-12)


# --------------------------------------------------------------------------- suite


def test_standard_leaves_out_inactive_stages():
    channels = ("r", "psi")
    suite = SensorSuite.standard(channels, noise_std=0.0, bias={"r": 0.0}, quantization=None,
                                 delay=0, dropout={"psi": 0.0})
    assert suite.stages == []
    suite.bind(2)
    np.testing.assert_array_equal(suite.measure(np.array([[1.0, 2.0], [3.0, 4.0]])),
                                  [[1.0, 2.0], [3.0, 4.0]])
    assert suite.valid.all()


def test_standard_stage_order():
    suite = SensorSuite.standard(("r", "psi"), bias={"r": 0.1}, noise_std={"psi": 0.1},
                                 wrap=("psi",), quantization={"r": 0.5}, delay={"psi": 1},
                                 dropout={"r": 0.1})
    assert [type(s) for s in suite.stages] == [Bias, GaussianNoise, WrapAngle, Quantizer, Delay,
                                               Dropout]
    zooming = SensorSuite.standard(("r", "psi"), quantization={"r": 1.0}, quantizer="zooming")
    assert [type(s) for s in zooming.stages] == [ZoomingQuantizer]


def test_standard_quantizes_after_bias():
    suite = SensorSuite.standard(("r",), bias=0.3, quantization=1.0)
    suite.bind(3)
    z = np.array([[0.3], [0.1], [-0.9]])
    out = suite.measure(z.copy())
    np.testing.assert_array_equal(out, quantize(z + 0.3, 1.0))  # q(z + b), not q(z) + b
    assert out[0, 0] == 1.0


@pytest.mark.parametrize("argument", ["bias", "noise_std", "quantization", "delay", "dropout"])
def test_standard_rejects_unknown_channel(argument):
    with pytest.raises(ValueError, match=rf"{argument}.*'yaw'"):
        SensorSuite.standard(("r", "psi"), **{argument: {"yaw": 0.1}})


def test_standard_rejects_unknown_wrap_channel():
    with pytest.raises(ValueError, match=r"wrap.*'yaw'"):
        SensorSuite.standard(("r", "psi"), wrap=("yaw",))


# --------------------------------------------------------------------------- per_channel


def test_per_channel_expansion():
    channels = ("a", "b", "c")
    np.testing.assert_array_equal(per_channel("x", 2.5, channels), [2.5, 2.5, 2.5])
    np.testing.assert_array_equal(per_channel("x", {"b": 1.0}, channels), [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(per_channel("x", {"b": 1.0}, channels, default=7.0),
                                  [7.0, 1.0, 7.0])
    np.testing.assert_array_equal(per_channel("x", None, channels), [0.0, 0.0, 0.0])
    assert np.isnan(per_channel("x", None, channels, default=math.nan)).all()
    with pytest.raises(ValueError, match=r"x: unknown channel\(s\) \['d'\]"):
        per_channel("x", {"d": 1.0}, channels)
