"""A reset costs about a step, with the same numbers: the wave block of a reset boat summed with
its gains interpolated once (steady Hs), the channels a sea does not move left out, BLAS on one
thread inside the step (marine_envs.blas), initial states of many boats in one operation."""

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from marine_envs.blas import one_blas_thread
from marine_envs.blocks import BLOCK
from marine_envs.envs.core import UniformInitialState
from marine_envs.models import get_model
from marine_envs.sea import SeaState, WaveRealisation, wave_coupling
from marine_envs.sea.waves import BLAS_FROM, _shaped_block

DT = 0.05
#: Hs holds for 20 s (steady blocks), then ramps (blocks whose gains change step by step).
SCHEDULE = [(0.0, 0.1), (20.0, 0.1), (40.0, 0.3)]


def _hydrofoil_sea(**kwargs):
    coupling = wave_coupling(get_model("hydrofoil"), 2.0, **kwargs)
    return WaveRealisation(SeaState(hs=SCHEDULE, tp=None), coupling, dt=DT, n_components=40)


def _blas_threads() -> dict[str, int]:
    """Threads of each BLAS library loaded, by its package (numpy, scipy, ...)."""
    return {Path(p["filepath"]).parent.name.split(".")[0]: p["num_threads"]
            for p in threadpool_info() if p["user_api"] == "blas"}


@pytest.mark.parametrize("start", [0.0, BLOCK * DT, 3 * BLOCK * DT], ids=["first", "steady",
                                                                            "ramp"])
def test_lone_block_equals_the_step_by_step_sum(start):
    sea = _hydrofoil_sea(rich=True)
    phasor = np.exp(1j * np.random.default_rng(4).uniform(0, 2 * math.pi, sea.omega.size))
    width = BLOCK * sea.n_channels
    fast, reference = np.empty(width), np.empty(width)
    sea._lone_block(phasor, start, fast)
    _shaped_block(phasor.real.copy(), phasor.imag.copy(), *sea._shaping,
                  *sea._hs_rows(start), reference)
    steady = sea._block_rows(start)[1] is not None
    assert steady == (start + BLOCK * DT <= 20.0)  # the fast path is taken where Hs holds
    np.testing.assert_array_equal(fast, reference)  # bitwise, not approximately


def test_unmoved_channels_are_zero_and_the_others_unchanged():
    # the paper's model moves only the two heave-velocity channels; the rich one all six,
    # the first two with the same coupling
    paper, rich = _hydrofoil_sea(), _hydrofoil_sea(rich=True)
    a, b = (sea.sample(3 * BLOCK, np.random.default_rng(7)) for sea in (paper, rich))
    assert a.shape == b.shape == (3 * BLOCK, 6)
    assert paper._moved == slice(0, 2) and rich._moved is None
    np.testing.assert_array_equal(a[:, 2:], 0.0)
    assert not np.signbit(a[:, 2:]).any()  # +0, as the sums of zeros were
    np.testing.assert_array_equal(a[:, :2], b[:, :2])


def test_one_blas_thread_inside_and_the_users_setting_after():
    # numpy's BLAS is the one the step's products use (scipy may load a BLAS of its own later)
    with threadpool_limits(limits=2, user_api="blas"):
        users = _blas_threads()
        with one_blas_thread():
            assert _blas_threads()["numpy"] == 1
        assert _blas_threads() == users


def test_reset_boats_waves_do_not_depend_on_blas_threads():
    # a group of reset boats is one BLAS product; OpenBLAS splits it between its threads by
    # rows and rounds a split's edge row differently: the environment runs it on one thread,
    # so the numbers are the same whatever the machine's (or the user's) thread count
    boats = 41  # an odd group: its rows split unevenly between two threads
    assert boats >= BLAS_FROM
    blocks = []
    for threads in (2, 1):
        sea = _hydrofoil_sea()
        sea.bind(boats)
        with threadpool_limits(limits=threads, user_api="blas"):
            users = _blas_threads()  # (a library built for one thread stays at one)
            sea.reset(np.arange(boats), [np.random.default_rng(i) for i in range(boats)])
            blocks.append(sea.stream.blocks.copy())
            assert _blas_threads() == users  # the user's setting is left alone
    np.testing.assert_array_equal(blocks[0], blocks[1])


def test_batch_initial_states_equal_boat_by_boat():
    initial = UniformInitialState(np.array([1.0, -2.0, 0.5]), np.array([0.1, 0.0, 2.0]))
    one_by_one = [np.random.default_rng(s) for s in range(5)]
    together = [np.random.default_rng(s) for s in range(5)]
    expected = np.stack([initial(rng) for rng in one_by_one])
    np.testing.assert_array_equal(initial.batch(together), expected)
    # and each generator is left where a call would leave it
    assert [r.random() for r in together] == [r.random() for r in one_by_one]


def test_vector_env_restarts_equal_single_envs_under_zero_action():
    # the hydrofoil broaches every ~25 steps under zero action: many boats restart together
    # (one group, one product), and each boat's record is its single environment's
    n, steps = 3, 120
    vec = gym.make_vec("marine_envs/Hydrofoil-v0", num_envs=n,
                       vectorization_mode="vector_entry_point", noise_std=None)
    obs, _ = vec.reset(seed=30)
    zero = np.zeros((n, 2), dtype=np.float32)
    rows, ends = [obs], []
    for _ in range(steps):
        obs, _, terminated, truncated, _ = vec.step(zero)
        rows.append(obs)
        ends.append(terminated | truncated)
    assert np.sum(ends) >= 3 * n  # several episodes per boat
    together = np.stack(rows, axis=1)
    for boat in range(n):
        env = gym.make("marine_envs/Hydrofoil-v0", noise_std=None)
        obs, _ = env.reset(seed=30 + boat)
        alone, finished = [obs], False
        for _ in range(steps):
            if finished:  # the vector env's NEXT_STEP autoreset: a step that only resets
                obs, _ = env.reset()
            else:
                obs, _, terminated, truncated, _ = env.step(zero[0])
            finished = not finished and (terminated or truncated)
            alone.append(obs)
        np.testing.assert_allclose(together[boat], np.stack(alone), rtol=0, atol=1e-6)
