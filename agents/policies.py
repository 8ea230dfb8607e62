"""Every policy by name, one name a policy: what ``marine simulate --policy``, ``marine episode
--policy``, ``marine bench --controllers`` and :func:`agents.evaluation.evaluate` accept.

* ``nominal``: the vehicle's nominal (trim) input whatever it sees, the do-nothing baseline
  (single and batched environments); ``zero``, its old name in ``marine simulate`` and
  ``marine episode``, is still accepted with a :class:`DeprecatedPolicyName` warning;
* ``sine``, ``random``, ``prbs``: open-loop excitations about the nominal input
  (:mod:`agents.excitation`; single environments);
* ``lqr``: the task's discrete LQR on what the environment gives (its sensors, an estimator's
  estimate, or the true state behind :data:`estimators.registry.ORACLE`); with ``amplitude``
  (and ``hold``), plus a random-step dither on every input, a closed-loop identification
  experiment (single environments);
* ``lqr-state``: the task's LQR fed the true state whatever the environment shows, the oracle
  baseline (single environments).

Trained agents are not named here: ``marine bench`` trains its own (``ppo``, ...) and takes
saved ones as ``sb3:DIR``.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np

NOMINAL, LQR, LQR_STATE = "nominal", "lqr", "lqr-state"
#: Hold time of the dither on ``lqr``, s: the random steps the diagnosis's own generator uses.
DITHER_HOLD = 2.0


@dataclasses.dataclass(frozen=True)
class NamedPolicy:
    """A policy of the registry: its one ``name``, what it does (``summary``), whether it acts
    on a batch of boats (a native vector environment) and the options it takes."""

    name: str
    summary: str
    batched: bool = False
    options: tuple[str, ...] = ()


#: The policies by name, in the order the command line lists them.
POLICIES: dict[str, NamedPolicy] = {p.name: p for p in (
    NamedPolicy(NOMINAL, "the vehicle's nominal (trim) input whatever it sees", batched=True),
    NamedPolicy("sine", "amplitude * sin(2 pi t / period) about the nominal input",
                options=("amplitude", "period")),
    NamedPolicy("random", "uniform random levels held for hold s about the nominal input",
                options=("amplitude", "hold")),
    NamedPolicy("prbs", "+-amplitude random levels held for hold s about the nominal input",
                options=("amplitude", "hold")),
    NamedPolicy(LQR, "the task's LQR on what the environment gives; with amplitude, plus a "
                     "random-step dither", batched=True, options=("amplitude", "hold")),
    NamedPolicy(LQR_STATE, "the task's LQR on the true state (an oracle baseline)"),
)}
#: Old names still accepted: old name -> the policy's one name.
ALIASES = {"zero": NOMINAL}


class DeprecatedPolicyName(FutureWarning):
    """A policy was named by an old name (:data:`ALIASES`): it still works, for now."""


def names(batched: bool | None = None) -> tuple[str, ...]:
    """The policies' names (only those that act on a batch of boats, or only those that do
    not, when ``batched`` is given)."""
    return tuple(name for name, policy in POLICIES.items()
                 if batched is None or policy.batched == batched)


def canonical(name: str) -> str:
    """The one name of the policy ``name`` names (an old name warns,
    :class:`DeprecatedPolicyName`).

    :raises ValueError: no policy has that name.
    """
    if name in ALIASES:
        warnings.warn(f"policy {name!r} is now called {ALIASES[name]!r}: the old name will go",
                      DeprecatedPolicyName, stacklevel=2)
        return ALIASES[name]
    if name not in POLICIES:
        raise ValueError(f"unknown policy {name!r}; choose from {', '.join(POLICIES)}")
    return name


def make_policy(name: str, env: Any, seed: int | None = None, estimator: str | None = None,
                **options: float) -> Any:
    """The policy ``name`` for ``env``, with SB3's ``predict``.

    :param env: a marine environment (single, or a native vector env for a batched policy),
        possibly wrapped.
    :param seed: seeds a random excitation or dither.
    :param estimator: what the environment's observation is (a name of
        :func:`estimators.registry.observe`): ``lqr`` behind ``"true"`` acts on the full state.
    :param options: the policy's options (:attr:`NamedPolicy.options`): ``amplitude`` (a share
        of each actuator's half range), ``period`` (s), ``hold`` (s).
    :raises ValueError: an unknown name, or an option the policy does not take.
    """
    name = canonical(name)
    unknown = sorted(set(options) - set(POLICIES[name].options))
    if unknown:
        takes = " and ".join(POLICIES[name].options) or "no options"
        raise ValueError(f"policy {name!r} takes {takes}, not {unknown}")
    if name == NOMINAL:
        return NominalInput(env)
    if name == LQR:
        return _lqr(env, seed, estimator, **options)
    if name == LQR_STATE:
        from .lqr import LQRPolicy

        return OnTrueState(env, LQRPolicy.for_env(env, observed=None))
    from .excitation import SIGNALS

    if name in ("random", "prbs"):
        options = {**options, "seed": seed}
    signal = SIGNALS[name](env.action_space.shape[0], env.unwrapped.dt, **options)
    system = env.unwrapped.system
    signal.centre = system.actuation.nominal_action(system.model)
    return signal


def _lqr(env: Any, seed: int | None, estimator: str | None, **options: float) -> Any:
    """``lqr``: on the full state behind the true-state observation, else on what ``env``
    gives; with ``amplitude``, plus a random-step dither held ``hold`` s."""
    from estimators.registry import ORACLE

    from .excitation import Dithered, RandomSteps
    from .lqr import LQRPolicy

    lqr = LQRPolicy.for_env(env, observed="state" if estimator == ORACLE else "auto")
    if not options.get("amplitude"):
        if "hold" in options:
            raise ValueError("policy 'lqr': a dither hold needs a dither amplitude")
        return lqr
    dither = RandomSteps(env.action_space.shape[0], env.unwrapped.dt, seed=seed,
                         amplitude=options["amplitude"], hold=options.get("hold", DITHER_HOLD))
    return Dithered(lqr, dither)


class NominalInput:
    """The vehicle's nominal (trim) input whatever it sees: the do-nothing baseline, one action
    per observation (a single environment's, or a batch's)."""

    def __init__(self, env: Any) -> None:
        # clipped as an excitation's actions are (the nominal action lies inside the range)
        system = env.unwrapped.system
        nominal = system.actuation.nominal_action(system.model)
        self.action = np.clip(nominal, -1.0, 1.0).astype(np.float32)

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        obs = np.asarray(observation)
        return np.broadcast_to(self.action, (*obs.shape[:-1], self.action.size)).copy(), None


class OnTrueState:
    """A policy fed the true state (``info["state"]``) instead of the observation: an oracle
    baseline, the best an estimator could give the controller (a single environment)."""

    def __init__(self, env: Any, policy: Any) -> None:
        self.env, self.policy = env.unwrapped, policy

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        return self.policy.predict(self.env.true_state, state, episode_start, deterministic)
