"""The batched extended Kalman filter, with parameters appended to the state, and the
Rauch-Tung-Striebel smoother.

One idea a module:

* :mod:`estimators.ekf.filter`: :class:`ExtendedKalmanFilter` (the estimator contract, offline
  runs, the filter of a vehicle model and of an environment);
* :mod:`estimators.ekf.kernels`: its predict and update compiled, every filter of a batch in
  one call, for a model with compiled equations;
* :mod:`estimators.ekf.dynamics`: what those kernels integrate: a model's compiled equations
  and the parameters it declares compiled (no vehicle known here);
* :mod:`estimators.ekf.smoother`: :class:`FilterResult`, :class:`SmootherResult` and
  :func:`rts_smooth`.
"""

from .filter import Dynamics, ExtendedKalmanFilter, FloatArray, Jacobian
from .smoother import FilterResult, SmootherResult, rts_smooth

__all__ = ["Dynamics", "ExtendedKalmanFilter", "FilterResult", "FloatArray", "Jacobian",
           "SmootherResult", "rts_smooth"]

# documented (and pickled) where they are imported from: this package, not its modules
for _public in (ExtendedKalmanFilter, FilterResult, SmootherResult, rts_smooth):
    _public.__module__ = __name__
