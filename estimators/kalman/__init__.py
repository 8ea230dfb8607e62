"""Batched discrete-time Kalman filters: the textbook one and the hydrofoil AKF paper's AKF.

One idea a module:

* :mod:`estimators.kalman.filter`: :class:`KalmanFilter`, a batch of linear filters sharing one
  model (covariances held once while the filters agree);
* :mod:`estimators.kalman.adaptive`: :class:`AdaptiveKalmanFilter`, the process noise switched
  by the chi-square test of each filter's innovation;
* :mod:`estimators.kalman.kernels`: the filters' one implementation of the predict and update,
  compiled, per filter or per shared covariance;
* :mod:`estimators.kalman.design`: the filter of a vehicle model and of an environment (the
  model linearised and discretised; the process and measurement noise of its disturbances and
  sensors).
"""

from .adaptive import AdaptiveKalmanFilter
from .design import (  # the private ones: what the sibling filters import from here
    _output_matrix,  # noqa: F401
    _wrap,  # noqa: F401
    _wrapped_channels,  # noqa: F401
    default_measurement_noise,
    default_process_noise,
    held_noise_covariance,
    linearised_model,
    wrapped_channel_names,
)
from .filter import KalmanFilter

__all__ = ["AdaptiveKalmanFilter", "KalmanFilter", "default_measurement_noise",
           "default_process_noise", "held_noise_covariance", "linearised_model",
           "wrapped_channel_names"]

# documented (and pickled) where they are imported from: this package, not its modules
for _name in __all__:
    globals()[_name].__module__ = __name__
