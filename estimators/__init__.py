"""State estimators of the source documents, batched, with Gymnasium wrappers.

* :class:`KalmanFilter`, :class:`AdaptiveKalmanFilter` (the hydrofoil AKF paper):
  :mod:`estimators.kalman`; built for an environment with its disturbances' own models (waves,
  current, wind, events as states; model error and prior from the env's own models),
  :func:`disturbance_filter`: :mod:`estimators.disturbance`;
* :class:`ExtendedKalmanFilter`, with model parameters appended to the state, and the RTS
  smoother :func:`rts_smooth` (the morphing-robot patent, the DP wave-frequency patent, the
  hovercraft EKF paper): :mod:`estimators.ekf`; its unscented variant
  :class:`UnscentedKalmanFilter`: :mod:`estimators.ukf`;
* the DP wave-frequency patent's pipeline (window, spectrum, Butterworth high-pass, EKF,
  acceptance) and the DP wave filter it retunes, :class:`WaveFrequencyWrapper`:
  :mod:`estimators.wave_frequency`;
* identification of model parameters from records (joint EKF, least squares, identifiability and
  negative-damping checks): :mod:`estimators.identification`;
* the USV observer patent's quantized-signal PD observer, :class:`QuantizedPDObserver`, and its
  LMI design :func:`design_pd_observer` (needs cvxpy: ``pip install "marine-envs[estimators]"``):
  :mod:`estimators.pd_observer`; the classical :class:`LuenbergerObserver`:
  :mod:`estimators.luenberger`;
* :class:`EstimatorWrapper`, :class:`VectorEstimatorWrapper`, :func:`wrap` and the oracle
  :class:`TrueStateWrapper`:
  :mod:`estimators.wrappers`;
* every estimator by name (what the CLI, the evaluation path and the benchmark accept):
  :mod:`estimators.registry`;
* the mismatch diagnosis of a recording against its model: :mod:`estimators.diagnosis`.

Every estimator follows :class:`estimators.base.Estimator` (docs/architecture.md contract 3).
"""

from .base import Estimator
from .disturbance import disturbance_filter
from .ekf import ExtendedKalmanFilter, rts_smooth
from .kalman import AdaptiveKalmanFilter, KalmanFilter
from .luenberger import LuenbergerObserver
from .pd_observer import LMIInfeasibleError, QuantizedPDObserver, design_pd_observer
from .ukf import UnscentedKalmanFilter
from .wave_frequency import AdaptiveWaveFilter, WaveFilter, WaveFrequencyWrapper
from .wrappers import EstimatorWrapper, TrueStateWrapper, VectorEstimatorWrapper, wrap

__all__ = ["AdaptiveKalmanFilter", "AdaptiveWaveFilter", "Estimator", "EstimatorWrapper",
           "ExtendedKalmanFilter", "KalmanFilter", "LMIInfeasibleError", "LuenbergerObserver",
           "QuantizedPDObserver", "TrueStateWrapper", "UnscentedKalmanFilter",
           "VectorEstimatorWrapper", "WaveFilter", "WaveFrequencyWrapper", "design_pd_observer",
           "disturbance_filter", "rts_smooth", "wrap"]
