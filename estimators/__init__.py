"""State estimators of the source documents, batched, with Gymnasium wrappers.

* :class:`KalmanFilter`, :class:`AdaptiveKalmanFilter` (seed 001) in :mod:`estimators.kalman`;
* the quantized-signal PD observer of seed 000 in :mod:`estimators.pd_observer` (needs cvxpy:
  ``pip install "marine-envs[estimators]"``);
* :class:`EstimatorWrapper`, :class:`VectorEstimatorWrapper` in :mod:`estimators.wrappers`.

Every estimator follows :class:`estimators.base.Estimator` (ARCHITECTURE.md contract 3).
"""

from .base import Estimator
from .kalman import AdaptiveKalmanFilter, KalmanFilter
from .wrappers import EstimatorWrapper, VectorEstimatorWrapper, wrap

__all__ = ["AdaptiveKalmanFilter", "Estimator", "EstimatorWrapper", "KalmanFilter",
           "VectorEstimatorWrapper", "wrap"]
