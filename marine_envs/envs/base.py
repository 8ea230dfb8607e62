"""Gymnasium front ends of the batched :class:`~marine_envs.envs.core.Simulator`.

:class:`MarineEnv` is a single environment (a batch of one); :class:`MarineVectorEnv` is its native
vector twin (a batch of N, no Python loop over boats while stepping), made for each vehicle by
:func:`vector_env`. Both follow docs/architecture.md contract 2: observations are sensor outputs,
``info["state"]`` is the true state, ``info["action_applied"]`` the physical input the actuators
applied, ``info["action_commanded"]`` the one the action commanded (clipped and scaled to the
model's input units, before any actuator effect of ``effects=``: a rate limit, saturation, dead
zone, delay or gain; the same values when there is none), and the reward is minus the task's
quadratic cost.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from numpy.typing import NDArray

from .. import plausibility
from ..compiled import first_use
from ..models.effects import Effect
from ..vessel import VesselDescription, read_vessel
from .core import Simulator
from .rendering import TimeSeriesRenderer
from .system import System

_ONE = np.array([0])
#: Builds the object whose ``draw(x, u, time)`` returns an RGB frame (and ``close()``);
#: default: strip charts (:class:`~marine_envs.envs.rendering.TimeSeriesRenderer`).
RendererFactory = Callable[[], Any]
#: A vehicle's own renderer class, built from its model.
Renderer = Callable[[Any], Any]


#: Effects for an environment: a vessel description (:mod:`marine_envs.vessel`), the path of its
#: JSON or of a diagnosis JSON, or effects (objects or their dicts).
EffectsArg = VesselDescription | Sequence[Effect | Mapping[str, Any]] | str | Path


def _with_effects(make_simulator: Callable[..., Simulator], kwargs: Mapping[str, Any],
                  effects: EffectsArg, environment: str) -> Simulator:
    """The simulator of ``kwargs`` as the vessel ``effects`` describes it: its parameters under
    those of ``kwargs["params"]``, its effects added (:meth:`Simulator.add_effects`).

    :raises ValueError: a description of another vehicle than ``environment``'s (naming both),
        or a malformed one.
    """
    vessel = read_vessel(effects)
    sim = make_simulator(**kwargs)
    vessel.check_vehicle(sim.model.name, environment)
    if vessel.params:  # rebuilt: the parameters shape the sea coupling and the task too
        sim = make_simulator(**{**kwargs, "params": vessel.environment_params(
            kwargs.get("params"))})
    if vessel.effects:
        sim.add_effects(list(vessel.effects))
    return sim


def _check_render_mode(render_mode: str | None, metadata: dict[str, Any]) -> None:
    if render_mode is not None and render_mode not in metadata["render_modes"]:
        raise ValueError(f"render_mode={render_mode!r} is invalid: None or 'rgb_array'")


def _renderer(renderer: Renderer | None, sim: Simulator) -> RendererFactory:
    """The vehicle's renderer, or strip charts of the states the task weighs and the inputs."""
    if renderer is not None:  # (partials, not lambdas: an environment pickles)
        return functools.partial(renderer, sim.model)
    weighted = tuple(n for n, q in zip(sim.model.state_names, sim.task.q, strict=True) if q > 0)
    return functools.partial(TimeSeriesRenderer, sim.model, weighted)


def _vehicle(env_class: type) -> str:
    """The vehicle's name as in its environment's id: ``USVVectorEnv`` -> "USV"."""
    return env_class.__name__.removesuffix("VectorEnv").removesuffix("Env")


def _spaces(sim: Simulator) -> tuple[spaces.Box, spaces.Box]:
    action = spaces.Box(-1.0, 1.0, (sim.n_actions,), dtype=np.float32)
    high = sim.sensors.output_range.astype(np.float32)
    return action, spaces.Box(-high, high, dtype=np.float32)


class MarineEnv(gym.Env[np.ndarray, np.ndarray]):
    """A marine vehicle in waves, seen through its sensors; one boat.

    A vehicle's environment sets :attr:`make_simulator` (its keyword arguments are the
    environment's) and, optionally, :attr:`renderer`; :func:`vector_env` makes its vector twin.
    Actions are normalised to [-1, 1] per input and mapped linearly to the physical limits;
    larger actions are clipped (``info["action_clipped"]``), NaN or inf raises ``ValueError``;
    ``info["action_commanded"]`` is the physical input commanded, ``info["action_applied"]``
    the one the actuators applied (they differ only under actuator effects).
    ``effects=`` (every environment) makes it a described vessel: catalogue effects or their
    dicts add physics the nominal model leaves out; a vessel description
    (:mod:`marine_envs.vessel`) or the path of its JSON or of a diagnosis JSON sets the model's
    parameters too (``params=`` overrides them by name) and is refused for another vehicle, e.g.
    ``gym.make(ENV_ID, effects="diagnosis.json")`` to train on the vessel as recorded.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}
    #: Builds the vehicle's :class:`Simulator` from the environment's keyword arguments.
    make_simulator: ClassVar[Callable[..., Simulator]]
    #: The vehicle's own renderer class (built from the model), or None for strip charts.
    renderer: ClassVar[Renderer | None] = None

    def __init__(self, render_mode: str | None = None, effects: EffectsArg = (),
                 **kwargs: Any) -> None:
        _check_render_mode(render_mode, self.metadata)
        with first_use(_vehicle(type(self))):  # the model's equations, the step kernel
            sim = _with_effects(self.make_simulator, kwargs, effects, type(self).__name__)
            self._system = System.of(sim, _vehicle(type(self)))  # before any boat is bound
            sim.bind(1)
        plausibility.warn(plausibility.environment_arguments(self.make_simulator, kwargs), 3)
        self._sim, self.render_mode = sim, render_mode
        self._make_renderer = _renderer(type(self).renderer, sim)
        self.metadata = {**self.metadata, "render_fps": round(1 / sim.dt)}
        self.action_space, self.observation_space = _spaces(sim)
        self.dt = sim.dt
        self._renderer = None

    @property
    def model(self):
        """The vehicle model (physics only)."""
        return self._sim.model

    @property
    def system(self) -> System:
        """What is simulated (read-only): the contract between the environment and whatever
        designs from it (estimators, controllers, agents)."""
        return self._system

    @property
    def true_state(self) -> np.ndarray:
        """A copy of the boat's true state ``(n_x,)``, state units (for oracles and
        evaluation; changing it changes nothing)."""
        return self._sim.x[0].copy()

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode. ``options={"state": x0}`` sets the initial true state (state units)."""
        super().reset(seed=seed)
        x0 = _initial_state(self._sim, options)
        with first_use(_vehicle(type(self))):  # the disturbances' filters
            self._sim.reset(_ONE, [self.np_random], x0=x0)
        obs = self._sim.measure()[0].astype(np.float32)
        return obs, self._info()

    def step(self, action):
        y, reward, failed = self._sim.step(action)
        return y[0].astype(np.float32), float(reward[0]), bool(failed[0]), False, self._info()

    def _info(self) -> dict[str, Any]:
        # views, not copies: the simulator replaces these arrays every step, never writes them
        sim = self._sim
        return {"state": sim.x[0], "action_applied": sim.u[0],
                "action_commanded": sim.u_commanded[0],
                "action_clipped": bool(sim.clipped[0]),
                # without a sea the simulator never replaces d: a copy, not a shared view
                "disturbance": sim.d[0] if sim.disturbances is not None else sim.d[0].copy(),
                # a new array each step (or the read-only all-valid one): a view is safe
                "measurement_mask": sim.valid[0],
                "time": float(sim.steps[0]) * sim.dt}

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = self._make_renderer()
        return self._renderer.draw(self._sim.x[0], self._sim.u[0], self._sim.steps[0] * self.dt)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class MarineVectorEnv(VectorEnv):
    """N boats stepped together with array operations; equals N :class:`MarineEnv` given the same
    seeds (``reset(seed=s)`` seeds boat i with ``s + i``, as Gymnasium's SyncVectorEnv does).

    Episodes end by failure (``terminated``) or after ``max_episode_steps`` (``truncated``); a
    finished boat is reset on the next step (``AutoresetMode.NEXT_STEP``), its action ignored.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10,
                                          "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, sim: Simulator, num_envs: int, max_episode_steps: int | None,
                 render_mode: str | None = None, renderer: RendererFactory | None = None) -> None:
        if not (isinstance(num_envs, int | np.integer) and num_envs >= 1):
            raise ValueError(f"num_envs={num_envs!r} is invalid: an integer >= 1")
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps={max_episode_steps!r} is invalid: >= 1 or None")
        _check_render_mode(render_mode, self.metadata)
        self._make_renderer = renderer or _renderer(None, sim)
        self._sim, self.num_envs, self.max_episode_steps = sim, int(num_envs), max_episode_steps
        self.render_mode, self.dt = render_mode, sim.dt
        self.single_action_space, self.single_observation_space = _spaces(sim)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._system = System.of(sim, _vehicle(type(self)))  # before any boat is bound
        with first_use(_vehicle(type(self))):  # the step kernel
            sim.bind(self.num_envs)
        self._rngs: list[np.random.Generator] = []
        self._done = np.zeros(self.num_envs, dtype=bool)
        self._all = np.arange(self.num_envs)
        self._mask = np.ones(self.num_envs, dtype=bool)
        self._mask.flags.writeable = False
        self._renderer = None

    @property
    def system(self) -> System:
        """What is simulated (read-only), as :attr:`MarineEnv.system`."""
        return self._system

    @property
    def true_state(self) -> np.ndarray:
        """A copy of every boat's true state ``(num_envs, n_x)``, state units."""
        return self._sim.x.copy()

    def set_state(self, x: np.ndarray) -> np.ndarray:
        """Put every boat at the true state ``x`` ``(num_envs, n_x)`` (state units) within
        its episode (an experiment that carries its vessels on into another environment) and
        return what the sensors measure of it, ``(num_envs, m)``.

        :raises ValueError: ``x`` of another shape, or not finite (nothing changed).
        """
        x = np.asarray(x, dtype=float)
        shape = self._sim.x.shape
        if x.shape != shape or not np.isfinite(x).all():
            raise ValueError(f"state has shape {x.shape}; expected {shape}, finite")
        self._sim.x = x.copy()
        return self._sim.measure().astype(np.float32)

    def reset(self, *, seed: int | list[int | None] | None = None,
              options: dict[str, Any] | None = None):
        """Reset every boat. ``seed``: an int (boat i gets ``seed + i``), a list, or None."""
        if seed is None and not self._rngs:
            seed = [None] * self.num_envs
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else seed
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed: {len(seeds)} seeds for {self.num_envs} environments")
            self._rngs = [seeding.np_random(s)[0] for s in seeds]
        x0 = _initial_state(self._sim, options)
        with first_use(_vehicle(type(self))):  # the disturbances' filters
            self._sim.reset(self._all, self._rngs, x0=x0)
        self._done[:] = False
        return self._sim.measure().astype(np.float32), self._info()

    def step(self, actions):
        sim = self._sim
        restarting = self._done.any()  # boats to reset before they are measured
        y, reward, terminated = sim.step(actions, measure=not restarting)
        truncated = (sim.steps >= self.max_episode_steps) if self.max_episode_steps \
            else np.zeros(self.num_envs, dtype=bool)
        if restarting:
            idx = np.flatnonzero(self._done)
            sim.reset(idx, [self._rngs[i] for i in idx])
            reward[idx], terminated[idx], truncated[idx] = 0.0, False, False
            y = sim.measure()
        self._done = terminated | truncated
        return y.astype(np.float32), reward, terminated, truncated, self._info()

    def restart(self, idx: NDArray[np.intp]) -> tuple[np.ndarray, np.ndarray]:
        """Start new episodes of boats ``idx`` now rather than on the next step (the
        same-step reset SB3 expects); their episode generators carry on, as a single env's
        do across resets. Returns their first measurements ``(len(idx), m)`` and the valid
        channels, taken by those boats' sensors alone (:meth:`Simulator.measure_boats`)."""
        idx = np.asarray(idx, dtype=np.intp)
        self._sim.reset(idx, [self._rngs[i] for i in idx])
        self._done[idx] = False
        y, valid = self._sim.measure_boats(idx)
        return y.astype(np.float32), valid

    def _info(self) -> dict[str, Any]:
        sim, m = self._sim, self._mask
        return {"state": sim.x, "_state": m, "action_applied": sim.u, "_action_applied": m,
                "action_commanded": sim.u_commanded, "_action_commanded": m,
                "action_clipped": sim.clipped, "_action_clipped": m,
                "disturbance": sim.d if sim.disturbances is not None else sim.d.copy(),
                "_disturbance": m, "measurement_mask": sim.valid,
                "_measurement_mask": m, "time": sim.steps * sim.dt, "_time": m}

    def render(self):
        """Frames of every boat (a tuple of RGB arrays) in ``rgb_array`` mode."""
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = self._make_renderer()
        return tuple(self._renderer.draw(x, u, t * self.dt)
                     for x, u, t in zip(self._sim.x, self._sim.u, self._sim.steps, strict=True))

    def close_extras(self, **kwargs: Any) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def vector_env(single: type[MarineEnv], max_episode_steps: int = 1000) -> type[MarineVectorEnv]:
    """The native vector twin of the vehicle environment ``single``: ``num_envs`` boats of the
    same simulator stepped together, with ``single``'s keyword arguments (Gymnasium's
    ``vector_entry_point``).

    :param max_episode_steps: the twin's default episode length, steps (the registered one).
    """

    def __init__(self: MarineVectorEnv, num_envs: int = 1,
                 max_episode_steps: int | None = max_episode_steps,
                 render_mode: str | None = None, effects: EffectsArg = (),
                 **kwargs: Any) -> None:
        with first_use(_vehicle(single)):  # the model's equations
            sim = _with_effects(single.make_simulator, kwargs, effects, type(self).__name__)
        plausibility.warn(plausibility.environment_arguments(single.make_simulator, kwargs), 3)
        MarineVectorEnv.__init__(self, sim, num_envs, max_episode_steps, render_mode=render_mode,
                                 renderer=_renderer(single.renderer, sim))

    name = single.__name__.removesuffix("Env") + "VectorEnv"
    doc = (f"``num_envs`` boats of :class:`{single.__name__}` stepped together with array "
           "operations; keyword arguments as there.")
    return type(name, (MarineVectorEnv,), {"__init__": __init__, "__doc__": doc,
                                           "__module__": single.__module__,
                                           "__qualname__": name})


def _initial_state(sim: Simulator, options: dict[str, Any] | None):
    """The ``state`` reset option, validated; None when the initial state is to be drawn."""
    if not options:
        return None
    unknown = sorted(set(options) - {"state"})
    if unknown:
        raise ValueError(f"unknown reset option(s) {unknown}; known: state")
    if options.get("state") is None:
        return None
    x0 = np.asarray(options["state"], dtype=float)
    n_x = len(sim.model.state_names)
    if x0.shape != (n_x,) or not np.isfinite(x0).all():
        raise ValueError(f"options['state'] must be {n_x} finite values "
                         f"({', '.join(sim.model.state_names)}), got {x0.tolist()!r}")
    return x0
