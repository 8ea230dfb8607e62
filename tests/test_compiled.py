"""The compiled back end (marine_envs.compiled): each model's equations written once, the step
kernel and the compiled sensor chain equal to their numpy references, and a disk cache that
survives processes and follows edits across files."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401 - registers the environments
from marine_envs import ENVIRONMENTS
from marine_envs.models import get_model
from marine_envs.sensors import CompiledChain, GaussianNoise, Saturation, SensorSuite

#: The numpy right-hand sides the compiled equations replaced, evaluated on random states,
#: inputs and disturbances before they were removed (commit 58fb721).
REFERENCE = np.load(Path(__file__).parent / "data" / "numpy_rhs_reference.npz")
VARIANTS = {
    "usv": ("usv", {}), "usv_angle": ("usv", {"wave_input": "angle"}),
    "hydrofoil": ("hydrofoil", {}), "hydrofoil_added": ("hydrofoil", {"added_mass": True}),
    "hydrofoil_helmbold": ("hydrofoil", {"lift_slope": "helmbold"}),
    "rov": ("rov", {}), "rov_morph": ("rov", {}),
    "rov_ground": ("rov", {"current_inertia": "ground"}),
    "dp_vessel": ("dp_vessel", {}), "hovercraft": ("hovercraft", {}),
    "hovercraft_beta": ("hovercraft", {"N_Hbeta": -3e5, "N_Avvv": 10.0, "X_Huv": -50.0}),
    "nomoto": ("nomoto", {}),
}


def close(got, want, rtol=1e-12):
    """Equal to ``rtol`` of each column's scale (a column of a batch may be near zero)."""
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape
    scale = np.abs(want).max(axis=tuple(range(want.ndim - 1)), keepdims=True)
    error = np.abs(got - want)
    assert np.all(error <= rtol * scale), f"error {error.max():.3g} beyond {rtol} x scale"


@pytest.mark.parametrize("case", list(VARIANTS))
def test_compiled_equations_equal_the_numpy_ones_they_replaced(case):
    name, params = VARIANTS[case]
    model = get_model(name, **params)
    x, u = REFERENCE[f"{case}/x"], REFERENCE[f"{case}/u"]
    d = REFERENCE[f"{case}/d"] if f"{case}/d" in REFERENCE else None
    close(model.rhs(x, u, d), REFERENCE[f"{case}/rhs"])
    if f"{case}/calm" in REFERENCE:
        close(model.rhs(x, u), REFERENCE[f"{case}/calm"])
    close(model.u0, REFERENCE[f"{case}/u0"])
    # finite differences amplify the last bits of rhs by 1/eps
    for got, want in zip(model.linearize(), "ABE", strict=True):
        close(got, REFERENCE[f"{case}/{want}"], rtol=1e-7)
    for i in range(3):  # one boat, and a batch of one, are rows of the batch
        close(model.rhs(x[i], u[i], None if d is None else d[i]), REFERENCE[f"{case}/rhs"][i])


def test_per_row_parameters_and_replaced_parameters_equal_the_numpy_ones():
    usv, x, u, d = get_model("usv"), REFERENCE["usv/x"], REFERENCE["usv/u"], REFERENCE["usv/d"]
    wn, Tr = REFERENCE["usv_rows/wn"], REFERENCE["usv_rows/Tr"]
    close(usv.with_rows(wn=wn, Tr=Tr).rhs(x, u, d), REFERENCE["usv_rows/rhs"])
    close(usv.rhs_with(x, u, d, {"wn": wn, "zeta": 0.2}), REFERENCE["usv_rows/rhs_with"])
    nomoto = get_model("nomoto")
    rows = nomoto.with_rows(K=REFERENCE["nomoto_rows/K"], T=REFERENCE["nomoto_rows/T"])
    close(rows.rhs(REFERENCE["nomoto/x"], REFERENCE["nomoto/u"], REFERENCE["nomoto/d"]),
          REFERENCE["nomoto_rows/rhs"])
    for case in ("hovercraft", "hovercraft_beta"):  # affine parameters, one rhs call each
        name, params = VARIANTS[case]
        model = get_model(name, **params)
        x, u, d = (REFERENCE[f"{case}/{k}"] for k in "xud")
        close(model.rhs_with(x, u, d, {"N_Hr": REFERENCE[f"{case}/N_Hr"], "C_R4": 1.8}),
              REFERENCE[f"{case}/rhs_with"])


@pytest.mark.parametrize("case", ["rov", "rov_morph", "rov_ground"])
def test_rov_forces_regressors_and_parameter_jacobian_equal_the_numpy_ones(case):
    name, params = VARIANTS[case]
    model = get_model(name, **params)
    x, u, d = (REFERENCE[f"{case}/{k}"] for k in "xud")
    names = ["Xuu", "Nrr", "Zvp", "Yuv", "Xqq", "Mrp"]
    theta = {n: REFERENCE[f"{case}/theta"][:, j] for j, n in enumerate(names)}
    still = np.column_stack([np.zeros((len(x), 3)), d[:, 3]])
    close(model.rhs(x, u, still), REFERENCE[f"{case}/still"])
    close(model.forces(x, u, d), REFERENCE[f"{case}/forces"])
    close(model.hydrodynamic_regressors(x, names, d), REFERENCE[f"{case}/regressors"])
    close(model.rhs_with(x, u, d, theta), REFERENCE[f"{case}/rhs_with"])
    close(model.parameter_jacobian(x, u, d, theta), REFERENCE[f"{case}/jacobian"])
    close(model.trim_forces(1.2, 0.4), REFERENCE[f"{case}/trim_forces"])


@pytest.mark.parametrize("case", ["hydrofoil", "hydrofoil_added", "hydrofoil_helmbold"])
def test_the_hydrofoil_trim_is_the_numpy_one(case):
    name, params = VARIANTS[case]
    t = get_model(name, **params).trim
    close(np.concatenate([t.alpha_s0, [t.F0], t.L, t.C_L, t.D, [t.f], t.h]),
          REFERENCE[f"{case}/trim"])


# -- the step against the episodes the numpy path recorded ----------------------------------------
#: Episodes of the numpy path when it was a second implementation of the step
#: (tests/data/make_step_reference.py); the kernel and today's numpy path (the kernel's stages
#: over the batch's rows) both reproduce them.
STEP_REFERENCE = np.load(Path(__file__).parent / "data" / "step_reference.npz")
sys.path.insert(0, str(Path(__file__).parent / "data"))
import make_step_reference as episodes  # noqa: E402

BUSY = episodes.BUSY


def assert_recorded(got, prefix):
    """``got`` (:func:`episodes.run`) equals the recorded episode, to rounding (the numpy path
    summed the allocation, the cost and the exact step by BLAS products)."""
    want = {key: STEP_REFERENCE[f"{prefix}/{key}"] for key in got}
    close(got["state"], want["state"])
    close(got["reward"][..., None], want["reward"][..., None])
    np.testing.assert_allclose(got["obs"], want["obs"], rtol=1e-6, atol=1e-9)  # float32
    for key in ("action_applied", "disturbance"):
        np.testing.assert_allclose(got[key], want[key], rtol=1e-12, atol=1e-300)
    for key in ("action_clipped", "measurement_mask", "time", "terminated", "truncated"):
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)


@pytest.mark.parametrize("in_numpy", [False, True], ids=["kernel", "numpy"])
@pytest.mark.parametrize("env_id", list(ENVIRONMENTS))
def test_the_step_reproduces_the_numpy_path_s_recorded_episodes_and_resets(env_id, in_numpy):
    env = episodes.busy_env(env_id)
    assert env._sim.compiled
    if in_numpy:
        env = episodes.in_numpy(env)
        assert not env._sim.compiled
    got = episodes.run(env, episodes.SEED, episodes.busy_actions(env))
    assert_recorded(got, env_id)
    assert (got["terminated"] | got["truncated"]).sum() >= 3  # resets were exercised


def test_the_zigzag_law_runs_in_numpy_as_recorded():
    env = gym.make("marine_envs/Hovercraft-v0", zigzag=episodes.ZIGZAG)
    assert not env.unwrapped._sim.compiled
    actions = np.zeros((episodes.ZIGZAG_STEPS, *env.action_space.shape))
    assert_recorded(episodes.run(env, episodes.ZIGZAG_SEED, actions), "zigzag")


@pytest.mark.parametrize("env_id", ["marine_envs/USV-v0", "marine_envs/DPVessel-v0"])
def test_a_boat_restarted_between_steps_continues_as_a_single_env_reset_there(env_id):
    kw = {k: v for k, v in BUSY[env_id].items() if k != "max_roll"}  # no episode ends
    vector = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **kw)
    single = gym.make(env_id, **kw)
    vector.reset(seed=5)
    single.reset(seed=6)  # boat 1 of the vector env
    rng = np.random.default_rng(3)
    for step in range(300):
        action = rng.uniform(-0.2, 0.2, vector.action_space.shape).astype(np.float32)
        if step == 120:  # boat 1 restarts now (as SB3 resets a finished env); its sensors alone
            obs, _ = vector.restart(np.array([1]))
            obs_single, _ = single.reset()
            np.testing.assert_array_equal(obs[0], obs_single)
            continue
        obs, *_, info = vector.step(action)
        obs_single, *_, info_single = single.step(action[1])
        np.testing.assert_array_equal(obs[1], obs_single, err_msg=f"step {step}")
        np.testing.assert_array_equal(info["state"][1], info_single["state"])


def test_a_diverging_boat_is_named_and_the_step_not_taken():
    env = gym.make_vec("marine_envs/Hydrofoil-v0", num_envs=3,
                       vectorization_mode="vector_entry_point")
    env.reset(seed=0)
    sim = env._sim
    sim.x = sim.x.copy()
    sim.x[1, 2] = np.inf  # boat 1's heave rate
    x, steps, noise = sim.x.copy(), sim.steps.copy(), sim._compiled.chain.noise.stream.cursor.copy()
    with pytest.raises(FloatingPointError, match="boat 1"):
        env.step(np.zeros((3, 2), dtype=np.float32))
    np.testing.assert_array_equal(sim.x, x)
    np.testing.assert_array_equal(sim.steps, steps)
    # the sensors untouched
    np.testing.assert_array_equal(sim._compiled.chain.noise.stream.cursor, noise)


def test_envs_with_a_zigzag_law_run_in_numpy_and_the_others_compiled_effects_too():
    compiled = [gym.make(env_id).unwrapped._sim.compiled for env_id in ENVIRONMENTS]
    assert all(compiled)
    effects = [{"effect": "linear_damping", "target": "r", "parameters": {"c": -0.1}},
               {"effect": "input_delay", "target": "delta", "parameters": {"tau": 0.3}}]
    assert gym.make("marine_envs/USV-v0", effects=effects).unwrapped._sim.compiled
    assert not gym.make("marine_envs/Hovercraft-v0", zigzag="20/20").unwrapped._sim.compiled


# -- the compiled sensor chain against the numpy stages it replaced --------------------------------
#: Chains measured stage by stage by the numpy stages (tests/data/make_sensor_reference.py).
SENSOR_REFERENCE = np.load(Path(__file__).parent / "data" / "sensor_reference.npz")
import make_sensor_reference as chains  # noqa: E402


@pytest.mark.parametrize("k", range(len(chains.CHAINS) + 1))
def test_the_chain_at_once_and_stage_by_stage_equal_the_numpy_stages_it_replaced(k):
    make = (lambda: SensorSuite.standard(chains.CHANNELS, **chains.CHAINS[k])) \
        if k < len(chains.CHAINS) else chains.zoom_law_suite
    suite, twin = make(), make()
    compiled = CompiledChain.of(twin)
    assert compiled is not None
    for s in (suite, twin):
        s.bind(chains.BOATS)
        s.reset(np.arange(chains.BOATS), [np.random.default_rng(i) for i in range(chains.BOATS)])
    compiled.bind(chains.BOATS)
    rng = np.random.default_rng(99)
    for step in range(chains.STEPS):
        z = chains.true_values(step, rng)
        if step % 97 == 50:  # boats restarting midway
            idx = np.array([1, 3])
            for s in (suite, twin):
                s.reset(idx, [np.random.default_rng(1000 + step + i) for i in range(2)])
        by_stage = suite.measure(z.copy())
        at_once, valid = compiled.measure(z.copy())
        want, want_valid = SENSOR_REFERENCE[f"{k}/y"][step], SENSOR_REFERENCE[f"{k}/valid"][step]
        np.testing.assert_array_equal(by_stage, want, err_msg=f"stage by stage, step {step}")
        np.testing.assert_array_equal(at_once, want, err_msg=f"at once, step {step}")
        np.testing.assert_array_equal(np.broadcast_to(suite.valid, want.shape), want_valid)
        np.testing.assert_array_equal(valid, want_valid)


def test_a_chain_of_other_stages_or_order_is_not_compiled():
    class Scale(GaussianNoise.__mro__[2]):  # a Stage of the user's own
        def __call__(self, z):
            return 2 * z

    assert CompiledChain.of(SensorSuite(("a",), [Scale()])) is None
    assert CompiledChain.of(SensorSuite(("a",), [Saturation([1.0]), GaussianNoise([0.1])])) \
        is None


# -- the disk cache --------------------------------------------------------------------------------
def run_python(code: str, cwd: Path) -> str:
    """``code``'s output in a new process whose numba cache is a folder of ``cwd``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cwd / "cache"))
    result = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=cwd, env=env,
                            capture_output=True, text=True, timeout=300, check=True)
    return result.stdout.strip()


def test_the_cache_survives_processes_and_follows_an_edit_in_another_file(tmp_path):
    (tmp_path / "equations.py").write_text(textwrap.dedent("""
        from marine_envs.compiled import jit

        @jit
        def core(x, u, d, p, out):
            out[0] = -p[0] * x[0] + u[0]
        """))
    (tmp_path / "kernels.py").write_text(textwrap.dedent("""
        from marine_envs.compiled import rows
        from equations import core

        over_rows = rows(core)  # a closure over the equations, in another file
        """))
    probe = """
        import numpy as np
        from kernels import over_rows
        out = np.empty((1, 1))
        over_rows(np.ones((1, 1)), np.ones((1, 1)), np.zeros((1, 0)), np.full((1, 1), 2.0), out)
        print(out[0, 0], sum(over_rows.stats.cache_hits.values()),
              sum(over_rows.stats.cache_misses.values()))
        """
    assert run_python(probe, tmp_path) == "-1.0 0 1"  # compiled and saved
    assert run_python(probe, tmp_path) == "-1.0 1 0"  # loaded: no compilation
    equations = tmp_path / "equations.py"
    equations.write_text(equations.read_text().replace("-p[0]", "-3 * p[0]"))
    assert run_python(probe, tmp_path) == "-5.0 0 1"  # the edited equations, compiled anew
