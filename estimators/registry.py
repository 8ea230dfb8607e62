"""Every estimator by name: what ``marine bench``, ``marine train``, ``marine episode`` and
:func:`agents.evaluation.evaluate` put between a vehicle's sensors and its controller.

A name is a factory ``env -> Estimator`` given the environment it will watch (single or native
vector, possibly wrapped); a factory raises ``ValueError`` where it does not apply (e.g. the USV
observer patent's observer off the USV). Two names are not estimators: ``"true"`` (the true
state, the oracle) and ``"raw"`` (the sensors themselves).

>>> from estimators.registry import observe
>>> venv = observe(gym.make_vec("marine_envs/USV-v0", 4, vectorization_mode="vector_entry_point"),
...                "kf")
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .base import Estimator

#: The true state (an oracle) and the raw sensors: observations that are not an estimator's.
ORACLE, RAW = "true", "raw"
Factory = Callable[[Any], Estimator]
#: ``name -> factory(env) -> estimator``, in the order the command line lists them.
ESTIMATORS: dict[str, Factory] = {}
#: ``name -> what it is``, a few words for help texts.
DESCRIPTIONS: dict[str, str] = {}


def register(name: str, factory: Factory, description: str = "") -> None:
    """Make ``name`` an estimator of :func:`observe` (and so of the benchmark and the CLI).

    :param factory: ``env -> estimator`` (:class:`estimators.base.Estimator`); raise
        ``ValueError`` where it does not apply to the env's vehicle.
    :param description: a few words for help texts.
    """
    if name in (ORACLE, RAW) or not name.isidentifier():
        raise ValueError(f"estimator name {name!r} is invalid: an identifier, not "
                         f"{ORACLE!r} or {RAW!r}")
    ESTIMATORS[name], DESCRIPTIONS[name] = factory, description


def names() -> tuple[str, ...]:
    """Every name :func:`observe` accepts: ``"true"``, ``"raw"`` and the registered ones."""
    return (ORACLE, RAW, *ESTIMATORS)


def describe() -> str:
    """The registered estimators and their descriptions, for help texts."""
    return ", ".join(f"{name} ({DESCRIPTIONS[name]})" if DESCRIPTIONS[name] else name
                     for name in ESTIMATORS)


def make(name: str, env: Any) -> Estimator:
    """The registered estimator ``name`` for ``env``.

    :raises ValueError: an unknown name (listing the known ones) or one that does not apply.
    """
    if name not in ESTIMATORS:
        raise ValueError(f"estimator={name!r} is unknown: one of {names()}")
    return ESTIMATORS[name](env)


def observe(env: Any, name: str) -> Any:
    """``env`` as its controller sees it through ``name``: the true state (``"true"``; a native
    vector env only), the sensors (``"raw"``: ``env`` itself) or a registered estimator's
    estimate (its wrapper; :func:`estimators.wrappers.wrap`)."""
    from .wrappers import TrueStateWrapper, wrap

    if name == ORACLE:
        return TrueStateWrapper(env)
    if name == RAW:
        return env
    return wrap(env, make(name, env))


# -- the estimators of the source documents -------------------------------------------------------
def _kf(env: Any) -> Estimator:
    """A Kalman filter of the env's model and its disturbances' own models (waves, current,
    wind, events), linearised at the reference (:mod:`estimators.disturbance`)."""
    from .disturbance import disturbance_filter

    return disturbance_filter(env)


def _akf(env: Any) -> Estimator:
    """The hydrofoil AKF paper's adaptive filter on the disturbance-model filter: process
    noise switched between the model's own (``Q_min``) and ten times it (the paper's WQmax /
    WQmin)."""
    from .disturbance import disturbance_filter

    return disturbance_filter(env, adaptive=True)


def _kf_sea(env: Any) -> Estimator:
    """The disturbance-model filter with the sea estimated online: a bank of them over a grid
    of peak periods and heights, weighted by their innovations' likelihood (the vehicles with
    wave channels: the USV and the hydrofoil)."""
    from .sea_bank import sea_bank_filter

    return sea_bank_filter(env)


def _kf_white(env: Any) -> Estimator:
    """A Kalman filter of the env's model alone, its disturbances taken as white noise of their
    sampled covariance."""
    from .kalman import KalmanFilter

    return KalmanFilter.for_env(env)


def _akf_white(env: Any) -> Estimator:
    """The adaptive filter on the white-noise filter."""
    from .kalman import AdaptiveKalmanFilter, default_process_noise

    Q = default_process_noise(env.unwrapped.system)
    return AdaptiveKalmanFilter.for_env(env, Q=Q, Q_max=10 * Q)


def _ekf(env: Any) -> Estimator:
    """An extended Kalman filter of the nonlinear model."""
    from .ekf import ExtendedKalmanFilter

    return ExtendedKalmanFilter.for_env(env)


def _pd_observer(env: Any) -> Estimator:
    """The USV observer patent's quantized-signal PD observer (LMI design; the USV only)."""
    from marine_envs.models import USVModel

    from .pd_observer import QuantizedPDObserver

    system = env.unwrapped.system
    if not isinstance(system.model, USVModel):
        raise ValueError(f"the USV observer patent's PD observer is designed for the USV, not "
                         f"{system.model.name}")
    return QuantizedPDObserver.for_usv(system.model, mu2=0.01, dt=system.dt)


def _wave_filter(env: Any) -> Estimator:
    """The DP vessel's wave filter (the DP wave-frequency patent's observer) with the vessel's
    own wave-frequency model (the DP vessel only)."""
    from .wave_frequency import WaveFilter

    w0 = getattr(env.unwrapped.system.model.params, "w0", None)  # off the DP vessel: refused
    return WaveFilter.for_env(env, **({} if w0 is None else {"w0": w0}))


def _adaptive_wave_filter(env: Any) -> Estimator:
    """The wave filter whose wave frequencies the DP wave-frequency patent's pipeline estimates
    online, from the patent's initial guess (the DP vessel only)."""
    from .wave_frequency import AdaptiveWaveFilter

    return AdaptiveWaveFilter.for_env(env)


register("kf", _kf, "a Kalman filter of the linearised model and its disturbances' models")
register("akf", _akf, "the hydrofoil AKF paper's adaptive Kalman filter on kf")
register("kf_sea", _kf_sea, "kf with the sea estimated online, USV and hydrofoil only")
register("kf_white", _kf_white, "a Kalman filter of the linearised model, white disturbances")
register("akf_white", _akf_white, "the adaptive Kalman filter on kf_white")
register("ekf", _ekf, "an extended Kalman filter of the nonlinear model")
register("pd", _pd_observer, "the USV observer patent's PD observer, USV only")
register("wave", _wave_filter, "the wave filter with the vessel's sea, DP vessel only")
register("wave_adaptive", _adaptive_wave_filter,
         "the wave filter with online wave-frequency estimation, DP vessel only")
