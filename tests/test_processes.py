"""Disturbance sources: Gauss-Markov processes, step events, stacking."""

import math

import numpy as np
import pytest

from marine_envs.sea.processes import GaussMarkov, Stacked, StepEvent


def start(source, n, seed=0):
    source.bind(n)
    source.reset(np.arange(n), [np.random.default_rng(seed + i) for i in range(n)])
    return source


def test_gauss_markov_has_its_mean_std_and_correlation_time():
    dt, tau = 0.1, 10.0
    source = start(GaussMarkov([1.0, -2.0], [0.5, 2.0], [tau, 0.0], dt=dt), 4)
    x = np.array([source.step() for _ in range(20000)])  # (steps, boats, channels)
    np.testing.assert_allclose(x.mean(axis=(0, 1)), [1.0, -2.0], atol=0.06)
    np.testing.assert_allclose(x.std(axis=(0, 1)), [0.5, 2.0], rtol=0.05)
    slow = x[:, :, 0] - 1.0
    lag = int(1.0 / dt)  # one second: correlation exp(-1/10)
    assert np.mean(slow[lag:] * slow[:-lag]) / slow.var() == pytest.approx(math.exp(-0.1), abs=0.03)
    white = x[:, :, 1] + 2.0
    assert abs(np.mean(white[1:] * white[:-1]) / white.var()) < 0.03


def test_gauss_markov_is_continuous_across_blocks_and_starts_stationary():
    source = start(GaussMarkov([0.0], [1.0], [50.0], dt=0.1), 200)
    first = source.step()[:, 0]
    assert first.std() == pytest.approx(1.0, rel=0.2)  # episodes start in the stationary law
    x = np.array([source.step()[:, 0] for _ in range(600)])  # crosses two block refills
    jumps = np.abs(np.diff(x, axis=0))
    # increments of an AR(1) with a = exp(-dt/T): std sqrt(2 (1 - a)), about 0.045 here
    assert jumps.max() < 8 * math.sqrt(2 * (1 - math.exp(-0.1 / 50)))


def test_infinite_time_constant_gives_a_constant_per_episode():
    source = start(GaussMarkov([3.0], [1.0], [math.inf], dt=0.5), 3)
    x = np.array([source.step()[:, 0] for _ in range(300)])
    np.testing.assert_array_equal(x, np.broadcast_to(x[0], x.shape))
    assert len(set(x[0])) == 3  # each boat draws its own


def test_a_boat_sees_the_same_signal_alone_or_in_a_batch():
    alone = start(GaussMarkov([0.0, 1.0], [1.0, 0.3], [5.0, 0.0], dt=0.1), 1, seed=2)
    batch = GaussMarkov([0.0, 1.0], [1.0, 0.3], [5.0, 0.0], dt=0.1)
    batch.bind(3)
    batch.reset(np.arange(3), [np.random.default_rng(s) for s in (0, 2, 5)])
    for _ in range(300):
        np.testing.assert_array_equal(alone.step()[0], batch.step()[1])


def test_step_event_switches_at_the_given_or_drawn_time():
    fixed = start(StepEvent([0.0], [1.0], dt=0.5, time=2.0), 2)
    values = np.array([fixed.step()[:, 0] for _ in range(8)])
    np.testing.assert_array_equal(values[:, 0], [0, 0, 0, 0, 1, 1, 1, 1])
    drawn = start(StepEvent([0.0], [1.0], dt=0.1, window=(1.0, 5.0)), 50)
    times = drawn.switch_time()
    assert times.min() >= 1.0 and times.max() <= 5.0 + 0.1 and len(set(times)) > 10
    with pytest.raises(ValueError, match="exactly one"):
        StepEvent([0.0], [1.0], dt=0.1)
    with pytest.raises(ValueError, match="window"):
        StepEvent([0.0], [1.0], dt=0.1, window=(5.0, 1.0))


def test_stacked_sources_concatenate_their_channels():
    source = start(Stacked(GaussMarkov([0.0, 0.0], [1.0, 1.0], [1.0, 1.0], dt=0.1),
                           StepEvent([7.0], [8.0], dt=0.1, time=0.0)), 2)
    value = source.step()
    assert value.shape == (2, 3) and np.all(value[:, 2] == 8.0)


@pytest.mark.parametrize("kwargs, name", [
    (dict(mean=[0.0], std=[-1.0], time_constant=[1.0]), "std"),
    (dict(mean=[0.0], std=[1.0], time_constant=[-1.0]), "time_constant"),
    (dict(mean=[0.0, 1.0], std=[1.0, 1.0, 1.0], time_constant=[1.0]), "std"),
])
def test_gauss_markov_rejects_bad_settings(kwargs, name):
    with pytest.raises(ValueError, match=name):
        GaussMarkov(dt=0.1, **kwargs)
