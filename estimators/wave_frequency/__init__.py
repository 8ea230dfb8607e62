"""Wave-frequency (WF) model estimation for the DP vessel and the wave filter it retunes (the DP
wave-frequency patent).

The patent's pipeline, per window of measured ``[north, east, psi]`` (m, m, rad; docs/models.md
4.2)::

    model-update flag set -> window (600 s; 300 s in the example), Ts from the data (0.5 s)
      -> spectrum fit in the WF band 0.3-1.6 rad/s            -> pre-estimate theta0 (rad/s)
      -> 10th-order Butterworth high-pass at 0.35 rad/s        -> WF motion y_wf
      -> EKF on [xi (6); omega_x, omega_y, omega_psi]          -> omega_hat (rad/s)
      -> accept if |omega_hat - theta0| < 0.2 rad/s per DOF    -> hand omega_hat to the wave
         filter and clear the flag; else discard and repeat on the next window.

:class:`WaveFrequencyEstimator` runs this online as a state machine (flag ``model_update``) and,
once a window is accepted, keeps monitoring the spectrum: when its peak leaves the accepted
frequencies by more than the acceptance tolerance on two checks in a row (a sea-state change),
it sets the flag again. :class:`WaveFilter` is the DP observer whose WF model is updated: a
Kalman filter on :class:`~marine_envs.models.dp_vessel.DPVesselModel` that separates the
low-frequency (LF) motion from the WF motion, with per-row peak frequencies that can be changed
without losing its state. :class:`AdaptiveWaveFilter` joins the two as one
:class:`~estimators.base.Estimator`; :class:`WaveFrequencyWrapper` puts it on ``DPVessel-v0``.

One module per step: :mod:`.config` (settings, input checks, constants; the units decision),
:mod:`.spectrum` (theta0), :mod:`.highpass` (the filter and its bias on omega),
:mod:`.window_ekf` (the EKF's realisations and process noise), :mod:`.window` (one window and
the acceptance test), :mod:`.online` (the state machine), :mod:`.wave_filter` (the DP observer),
:mod:`.adaptive` (the two joined, and the Gymnasium wrapper). Where the code deviates from the
patent, that module's docstring says why; the measured reasons are in the ``dp-wave-frequency``
reproduction.
"""

from .adaptive import AdaptiveWaveFilter, WaveFrequencyWrapper
from .config import (
    CHANNELS,
    DEG,
    LF_BAND,
    PARAMETER_NAMES,
    SEED_OMEGA_INITIAL,
    SEED_P0,
    SEED_Q,
    SEED_R,
    WF_BAND,
    FloatArray,
    WaveFrequencyConfig,
    sample_period,
)
from .highpass import highpass, highpass_bias, highpass_sos
from .online import WaveFrequencyEstimator, WindowEvent
from .spectrum import SpectralPeak, spectral_peak
from .wave_filter import WaveFilter
from .window import WindowEstimate, estimate_window
from .window_ekf import Realisation, run_ekf, wave_frequency_ekf

__all__ = ["AdaptiveWaveFilter", "CHANNELS", "DEG", "FloatArray", "LF_BAND", "PARAMETER_NAMES",
           "Realisation", "SEED_OMEGA_INITIAL", "SEED_P0", "SEED_Q", "SEED_R", "SpectralPeak",
           "WF_BAND", "WaveFilter", "WaveFrequencyConfig", "WaveFrequencyEstimator",
           "WaveFrequencyWrapper", "WindowEstimate", "WindowEvent", "estimate_window", "highpass",
           "highpass_bias", "highpass_sos", "run_ekf", "sample_period", "spectral_peak",
           "wave_frequency_ekf"]
