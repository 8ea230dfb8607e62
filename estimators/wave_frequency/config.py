"""Settings of the DP wave-frequency patent's pipeline, the checks of its input, and the shared
constants (measured channels, bands, the patent's noise and initial values).

**Units.** SI and radians everywhere. The patent's R = diag(1e-3, 1e-3, 2e-2) and P0 are read with
psi in **degrees** (2e-2 deg^2 is a 0.14 deg gyrocompass, next to 0.032 m position noise; in rad
it would be 8 deg of noise on 2 deg of WF yaw and the yaw estimate fails); they are converted
once (:data:`SEED_R`, :data:`SEED_P0`). The measured reasons are in the ``dp-wave-frequency``
reproduction.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
DEG = math.pi / 180
#: The measured channels, in order (m, m, rad).
CHANNELS = ("north", "east", "psi")
#: Names of the estimated WF peak frequencies (rad/s), appended to the EKF's state.
PARAMETER_NAMES = ("omega_x", "omega_y", "omega_psi")
#: The DP wave-frequency patent's bands, rad/s: low-frequency motion and wave-frequency motion.
LF_BAND = (0.0, 0.25)
WF_BAND = (0.3, 1.6)
#: The DP wave-frequency patent's EKF measurement noise diag(1e-3 m^2, 1e-3 m^2, 2e-2 deg^2),
#: in SI (rad^2).
SEED_R = (1e-3, 1e-3, 2e-2 * DEG**2)
#: The DP wave-frequency patent's P0 reordered to the EKF's state [xi_1 (3), xi_2 (3), omega (3)]
#: and in SI: the patent's order is [omega; xi_1; xi_2] with psi entries in deg (m^2 s^2, m^2,
#: (rad/s)^2).
SEED_P0 = (1e5, 1e5, 1e7 * DEG**2, 1e5, 1e5, 1e7 * DEG**2, 1e3, 1e3, 1e6)
#: The DP wave-frequency patent's Q_ident per 0.5 s step, same order and units as
#: :data:`SEED_P0`; used only with ``process_noise="seed"`` (it makes the estimate wander; see
#: :mod:`estimators.wave_frequency.window_ekf`).
SEED_Q = (5e-1, 5e-1, 1e-1 * DEG**2, 8e-1, 8e-1, 1e-1 * DEG**2, 5e-3, 5e-3, 5e-2)
#: The document's initial guess of the peak frequencies, rad/s.
SEED_OMEGA_INITIAL = (0.4, 0.4, 0.55)
_MIN_WINDOW_PERIODS = 5  # a window must hold this many periods of the band's lowest frequency


# -- configuration -----------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class WaveFrequencyConfig:
    """Settings of the pipeline; units SI (s, rad/s, m, rad). Defaults are the DP
    wave-frequency patent's.

    :param window: length of an estimation window, s (patent: 600; its example: 300).
    :param dt: expected sample period, s (patent: 0.5); data with a ``time`` column override it.
    :param band: the WF band searched for the spectral peak, rad/s.
    :param cutoff: high-pass cut-off, rad/s.
    :param order: Butterworth order of the high-pass.
    :param zero_phase: ``sosfiltfilt`` (True) or causal ``sosfilt`` (False).
    :param damping: relative damping lambda (zeta) of the WF model, -.
    :param omega_initial: the EKF's initial peak frequencies (x, y, psi), rad/s.
    :param R: EKF measurement-noise variances (m^2, m^2, rad^2).
    :param P0: EKF initial variances, state order [xi_1 (3), xi_2 (3), omega (3)].
    :param process_noise: ``"model"`` (the WF model's own, scaled to the data) or ``"seed"``
        (:data:`SEED_Q` literally, omega included).
    :param acquisition: run the acquisition pass before the document's EKF.
    :param refine_omega_std: prior std of omega in the refinement pass, rad/s.
    :param highpass_correction: subtract the high-pass bias of omega.
    :param tolerance: acceptance test ``|omega_hat - theta0| < tolerance``, rad/s (patent: 0.2).
    :param min_snr: a WF peak must stand this many times above the noise floor, -.
    :param monitor_window: data used by each sea-state check, s.
    :param monitor_every: period of the sea-state checks, s.
    :param change_threshold: a check fires when the spectral peak is this far from the accepted
        frequencies (any DOF), rad/s (default: the acceptance tolerance).
    :param change_confirmations: consecutive firing checks that set the model-update flag.
    """

    window: float = 600.0
    dt: float = 0.5
    band: tuple[float, float] = WF_BAND
    cutoff: float = 0.35
    order: int = 10
    zero_phase: bool = True
    damping: float = 0.1
    omega_initial: tuple[float, float, float] = SEED_OMEGA_INITIAL
    R: tuple[float, float, float] = SEED_R
    P0: tuple[float, ...] = SEED_P0
    process_noise: Literal["model", "seed"] = "model"
    acquisition: bool = True
    refine_omega_std: float = 0.1
    highpass_correction: bool = True
    tolerance: float = 0.2
    min_snr: float = 30.0
    monitor_window: float = 200.0
    monitor_every: float = 30.0
    change_threshold: float | None = None
    change_confirmations: int = 2

    def __post_init__(self) -> None:
        positive = ("window", "dt", "cutoff", "tolerance", "min_snr", "monitor_window",
                    "monitor_every", "refine_omega_std")
        for name in positive:
            _require_positive(name, getattr(self, name))
        lo, hi = _pair("band", self.band)
        object.__setattr__(self, "band", (lo, hi))
        if not 0 < self.damping < 1:
            raise ValueError(f"damping={self.damping!r} is invalid: must be in (0, 1)")
        if not (isinstance(self.order, int) and 1 <= self.order <= 20):
            raise ValueError(f"order={self.order!r} is invalid: an integer in [1, 20]")
        if self.process_noise not in ("model", "seed"):
            raise ValueError(f"process_noise={self.process_noise!r} is invalid: 'model' or 'seed'")
        for name, size in (("omega_initial", 3), ("R", 3), ("P0", 9)):
            vec = _vector(name, getattr(self, name), size)
            if not (vec > 0).all():
                raise ValueError(f"{name}={getattr(self, name)!r} is invalid: entries must be > 0")
            object.__setattr__(self, name, tuple(float(v) for v in vec))
        if self.change_threshold is not None:
            _require_positive("change_threshold", self.change_threshold)
        if not (isinstance(self.change_confirmations, int) and self.change_confirmations >= 1):
            raise ValueError(f"change_confirmations={self.change_confirmations!r} is invalid: "
                             "an integer >= 1")

    @property
    def threshold(self) -> float:
        """The sea-state change threshold in use, rad/s."""
        return self.tolerance if self.change_threshold is None else float(self.change_threshold)


def _require_positive(name: str, value: Any) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}={value!r} is invalid: must be a finite number > 0")


def _pair(name: str, value: Any) -> tuple[float, float]:
    vec = _vector(name, value, 2)
    if not 0 < vec[0] < vec[1]:
        raise ValueError(f"{name}={value!r} is invalid: need 0 < low < high (rad/s)")
    return float(vec[0]), float(vec[1])


def _vector(name: str, value: Any, size: int) -> FloatArray:
    try:
        vec = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is invalid: must be {size} numbers") from None
    if vec.size != size or not np.isfinite(vec).all():
        raise ValueError(f"{name}={value!r} is invalid: must be {size} finite numbers")
    return vec


# -- input checks ------------------------------------------------------------------------------
def sample_period(time: ArrayLike | None, dt: float | None = None, default: float = 0.5) -> float:
    """The sample period of a record, s: from its ``time`` column (s, uniform) if given, else
    ``dt``, else ``default``.

    :raises ValueError: non-uniform or non-increasing time, or ``dt`` disagreeing with it.
    """
    if time is None:
        value = default if dt is None else dt
        _require_positive("dt", value)
        return float(value)
    t = np.asarray(time, dtype=float).reshape(-1)
    if t.size < 2 or not np.isfinite(t).all():
        raise ValueError("time must hold at least 2 finite values (s)")
    steps = np.diff(t)
    Ts = float(np.median(steps))
    bad = np.flatnonzero(np.abs(steps - Ts) > 1e-3 * Ts)
    if Ts <= 0 or bad.size:
        k = int(bad[0]) if bad.size else 0
        raise ValueError(f"time is not uniformly sampled: step {k} is {steps[k]:.6g} s, the "
                         f"median step {Ts:.6g} s (Ts must be constant; resample first)")
    if dt is not None and not math.isclose(dt, Ts, rel_tol=1e-3):
        raise ValueError(f"dt={dt!r} s disagrees with the time column's step {Ts:.6g} s")
    return Ts


def _check_window(y: ArrayLike, dt: float, config: WaveFrequencyConfig) -> FloatArray:
    """``y`` as ``(T, N, 3)`` after the boundary checks (shape, finiteness, length, Nyquist)."""
    a = np.asarray(y, dtype=float)
    if a.ndim == 2:
        a = a[:, None, :]
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"y has shape {np.shape(y)}; expected (T, 3) or (T, N, 3): "
                         f"{', '.join(CHANNELS)} (m, m, rad)")
    bad = np.argwhere(~np.isfinite(a))
    if bad.size:
        k, _, c = bad[0]
        raise ValueError(f"y contains NaN or inf ({bad.shape[0]} values; first at sample {k}, "
                         f"channel {CHANNELS[c]!r}): fill or drop the gaps first")
    nyquist = math.pi / dt
    if nyquist <= config.band[1]:
        raise ValueError(f"dt={dt} s is too long: its Nyquist frequency {nyquist:.3g} rad/s "
                         f"does not reach the WF band's top {config.band[1]} rad/s")
    needed = _MIN_WINDOW_PERIODS * 2 * math.pi / config.band[0]
    if a.shape[0] * dt < needed:
        raise ValueError(f"window of {a.shape[0] * dt:g} s is too short: it must hold at least "
                         f"{_MIN_WINDOW_PERIODS} periods of {config.band[0]} rad/s "
                         f"({needed:.0f} s)")
    return a


def _rows(idx: ArrayLike | None, size: int) -> NDArray[np.intp]:
    rows = np.arange(size) if idx is None else np.atleast_1d(np.asarray(idx))
    return np.flatnonzero(rows) if rows.dtype == bool else rows.astype(np.intp)
