"""Parameter identification of vehicle models from manoeuvre data (the hovercraft EKF paper's
method, reusable).

Model-agnostic: everything works on a :class:`~marine_envs.models.VehicleModel` (its ``rhs_with``
and ``parameter_jacobian``), the names of the parameters to identify (fields of ``model.params``)
and data: one or several :class:`Segment` s (runs) of inputs and measurements
(:mod:`.data`). Three methods:

* :func:`identify_ekf` (:mod:`.joint_ekf`): the parameters appended to the state of an extended
  Kalman filter, the paper's method; several segments run as a batch of filters and their
  parameter posteriors are fused. :func:`identify_staged` (:mod:`.staged`) chains stages (e.g.
  linear coefficients from a mild manoeuvre, then the nonlinear ones from harder ones).
* :func:`identify_least_squares` with ``method="equation_error"`` (:mod:`.least_squares`): the
  accelerations regressed on ``d rhs / d theta``; no initial guess needed, but every state the
  fitted equations use must be measured.
* :func:`identify_least_squares` with ``method="output_error"`` (:mod:`.output_error`): simulated
  outputs fitted to the measured ones, initial states included.

Every method returns an :class:`Identification` (:mod:`.result`): estimates, standard deviations,
correlations and a verdict per parameter (identifiable or not, and why), with damping
coefficients of the energy-injecting sign flagged (:func:`damping_signs`).

Data convention (as :meth:`~estimators.ekf.ExtendedKalmanFilter.filter`): ``inputs[k]`` is held
from ``time[k]`` to ``time[k + 1]``; ``measurements[k]`` is taken at ``time[k]``. SI units,
radians; NaN is not allowed (drop or interpolate missing samples first).
"""

from .data import MIN_SAMPLES, FloatArray, Segment, as_segments, check_parameters, noise_std
from .joint_ekf import identify_ekf
from .least_squares import identify_least_squares
from .result import NULL_TOLERANCE, Identification, damping_signs
from .staged import Stage, identify_staged

__all__ = ["MIN_SAMPLES", "NULL_TOLERANCE", "FloatArray", "Identification", "Segment", "Stage",
           "as_segments", "check_parameters", "damping_signs", "identify_ekf",
           "identify_least_squares", "identify_staged", "noise_std"]
