"""Ocean wave spectra: parametric forms, measured spectra, NDBC files and spectrum fits.

Units throughout: angular frequency ``omega`` in rad/s, spectral density ``S(omega)`` in
m^2 s/rad (energy per rad/s), wave heights in m, periods in s. Measured spectra given per Hz
(m^2/Hz) are converted with ``omega = 2 pi f`` and ``S(omega) = S(f) / (2 pi)``, which keeps the
variance ``m0`` and hence ``Hs = 4 sqrt(m0)`` unchanged.
"""

from __future__ import annotations

import gzip
import math
from dataclasses import dataclass
from functools import lru_cache
from importlib.resources import files
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "MeasuredSpectrum",
    "NDBCSpectra",
    "SpectrumFit",
    "fit_spectrum",
    "jonswap",
    "ndbc_example_path",
    "peak_frequency",
    "pierson_moskowitz",
    "read_ndbc_spectra",
    "significant_wave_height",
    "spectral_moment",
]

PM_B_COEF = 3.11  # m^2/s^4: B = 3.11 / hs^2 in S = A w^-5 exp(-B w^-4), docs/models.md 2.5
# Peak of A w^-5 exp(-B w^-4) is at wp = (4B/5)^(1/4) = PM_WP_COEF / sqrt(hs).
PM_WP_COEF = (4.0 * PM_B_COEF / 5.0) ** 0.25
NDBC_EXAMPLE = "ndbc_46042_1996_jan.txt.gz"


# --------------------------------------------------------------------------- validation


def _positive(name: str, value: float) -> float:
    """Return ``value`` as float, or raise ValueError unless it is finite and > 0."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r} is invalid: must be a finite number > 0") from None
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f"{name}={value!r} is invalid: must be finite and > 0")
    return x


def _finite_array(name: str, values: ArrayLike) -> np.ndarray:
    """Float array copy of ``values``; raise ValueError naming the first non-finite index."""
    arr = np.array(values, dtype=float)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        i = tuple(int(k) for k in np.unravel_index(bad[0], arr.shape))
        idx = ", ".join(map(str, i))
        raise ValueError(f"{name}[{idx}]={float(arr[i])!r} is invalid: must be finite")
    return arr


def _spectrum_arrays(
    x_name: str,
    x: ArrayLike,
    y_name: str,
    y: ArrayLike,
    min_points: int = 2,
    allow_zero: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Validate a sampled spectrum: x 1-D, finite, > 0 (or >= 0), strictly increasing;
    y finite, >= 0."""
    xa = _finite_array(x_name, x)
    ya = _finite_array(y_name, y)
    if xa.ndim != 1 or xa.size < min_points:
        raise ValueError(
            f"{x_name} has shape {xa.shape}: must be 1-D with at least {min_points} points"
        )
    if ya.shape != xa.shape:
        raise ValueError(f"{y_name} has shape {ya.shape}: must match {x_name} shape {xa.shape}")
    nonpos = np.flatnonzero(xa < 0.0 if allow_zero else xa <= 0.0)
    if nonpos.size:
        i = int(nonpos[0])
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{x_name}[{i}]={float(xa[i])!r} is invalid: must be {bound}")
    step = np.flatnonzero(np.diff(xa) <= 0.0)
    if step.size:
        i = int(step[0]) + 1
        raise ValueError(
            f"{x_name}[{i}]={float(xa[i])!r} is invalid: must be strictly increasing "
            f"(previous value {float(xa[i - 1])!r})"
        )
    neg = np.flatnonzero(ya < 0.0)
    if neg.size:
        i = int(neg[0])
        raise ValueError(f"{y_name}[{i}]={float(ya[i])!r} is invalid: must be >= 0")
    return xa, ya


# --------------------------------------------------------------------------- parametric spectra


def _pm_shape(omega: np.ndarray, hs: float, wp: float) -> np.ndarray:
    """Two-parameter PM density; 0 for omega <= 0 without overflow warnings."""
    out = np.zeros(omega.shape)
    pos = omega > 0.0
    # x = wp/omega; beyond x = 6 the exponential is < 1e-700, so clip to keep x^5 finite.
    x = np.minimum(wp / omega[pos], 6.0)
    out[pos] = 5.0 / 16.0 * hs**2 / wp * x**5 * np.exp(-1.25 * x**4)
    return out


def pierson_moskowitz(omega: ArrayLike, hs: float, tp: float | None = None) -> np.ndarray:
    """Pierson-Moskowitz (ITTC/Bretschneider) spectrum.

    ``S = 5/16 hs^2 wp^4 omega^-5 exp(-5/4 (wp/omega)^4)`` with ``wp = 2 pi / tp``; its
    ``4 sqrt(m0)`` equals ``hs`` exactly. With ``tp=None`` the one-parameter, fully developed
    PM of docs/models.md 2.5 (``A = 8.1e-3 g^2``, ``B = 3.11/hs^2``) is used through its peak
    ``wp = (4B/5)^(1/4) = 1.256/sqrt(hs)``, normalised to the same ``hs``.

    :param omega: angular frequencies [rad/s], any shape; S = 0 where omega <= 0.
    :param hs: significant wave height [m], finite and > 0.
    :param tp: peak period [s], finite and > 0, or None for the one-parameter form.
    :return: spectral density [m^2 s/rad], same shape as ``omega``.
    """
    w = _finite_array("omega", omega)
    hs = _positive("hs", hs)
    wp = PM_WP_COEF / math.sqrt(hs) if tp is None else 2.0 * math.pi / _positive("tp", tp)
    return _pm_shape(w, hs, wp)


def _peak_enhancement(u: np.ndarray, gamma: float, sigma_a: float, sigma_b: float) -> np.ndarray:
    """JONSWAP factor gamma^r at normalised frequency u = omega/wp."""
    sigma = np.where(u <= 1.0, sigma_a, sigma_b)
    return gamma ** np.exp(-((u - 1.0) ** 2) / (2.0 * sigma**2))


@lru_cache(maxsize=256)
def _jonswap_norm(gamma: float, sigma_a: float, sigma_b: float) -> float:
    """Ratio of the JONSWAP shape's m0 to PM's at equal hs, tp (exact up to quadrature error).

    m0_J / m0_PM = 1 + 5 int p(u) (gamma^r - 1) du with p(u) = u^-5 exp(-5/4 u^-4), because
    int p du = 1/5. The integrand vanishes away from u = 1, so a fixed, fine grid covering
    +-12 sigma (and u >= 0.05, where p is ~ 0) gives it to ~1e-8.
    """
    lo = max(0.05, 1.0 - 12.0 * sigma_a)
    hi = 1.0 + 12.0 * sigma_b
    # u = 1 (the kink in sigma) is a node of both halves.
    u = np.concatenate([np.linspace(lo, 1.0, 4001), np.linspace(1.0, hi, 4001)[1:]])
    p = u**-5 * np.exp(-1.25 * u**-4)
    excess = _peak_enhancement(u, gamma, sigma_a, sigma_b) - 1
    return 1.0 + 5.0 * float(np.trapezoid(p * excess, u))


def jonswap(
    omega: ArrayLike,
    hs: float,
    tp: float,
    gamma: float = 3.3,
    sigma_a: float = 0.07,
    sigma_b: float = 0.09,
) -> np.ndarray:
    """JONSWAP spectrum: PM times the peak enhancement ``gamma**r``, normalised to ``hs``.

    ``r = exp(-(omega - wp)^2 / (2 sigma^2 wp^2))`` with ``sigma = sigma_a`` for
    ``omega <= wp`` and ``sigma_b`` above. The density is divided by the exact m0 ratio
    (numerical, cached), not the ``1 - 0.287 ln(gamma)`` approximation, so 4 sqrt(m0) = hs.

    :param omega: angular frequencies [rad/s], any shape; S = 0 where omega <= 0.
    :param hs: significant wave height [m], finite and > 0.
    :param tp: peak period [s], finite and > 0.
    :param gamma: peak enhancement factor [-], >= 1 (1 gives PM).
    :param sigma_a: peak width [-] below the peak, > 0.
    :param sigma_b: peak width [-] above the peak, > 0.
    :return: spectral density [m^2 s/rad], same shape as ``omega``.
    """
    w = _finite_array("omega", omega)
    hs = _positive("hs", hs)
    wp = 2.0 * math.pi / _positive("tp", tp)
    g = float(gamma)
    if not (math.isfinite(g) and g >= 1.0):
        raise ValueError(f"gamma={gamma!r} is invalid: must be finite and >= 1")
    sa = _positive("sigma_a", sigma_a)
    sb = _positive("sigma_b", sigma_b)
    enhancement = _peak_enhancement(w / wp, g, sa, sb)
    return _pm_shape(w, hs, wp) * enhancement / _jonswap_norm(g, sa, sb)


# --------------------------------------------------------------------------- spectral statistics


def spectral_moment(omega: ArrayLike, S: ArrayLike, n: float = 0) -> float:
    """Spectral moment ``m_n = int omega^n S(omega) d omega`` by the trapezoid rule.

    :param omega: angular frequencies [rad/s], 1-D, finite, >= 0 (> 0 if n < 0), strictly
        increasing.
    :param S: spectral density [m^2 s/rad], same length, finite, >= 0.
    :param n: order of the moment [-]; m_n is in m^2 (rad/s)^n.
    :return: the moment m_n.
    """
    order = float(n)
    if not math.isfinite(order):
        raise ValueError(f"n={n!r} is invalid: must be finite")
    w, s = _spectrum_arrays("omega", omega, "S", S, allow_zero=order >= 0)
    return float(np.trapezoid(w**order * s, w))


def significant_wave_height(omega: ArrayLike, S: ArrayLike) -> float:
    """Spectral significant wave height ``Hm0 = 4 sqrt(m0)`` [m].

    :param omega: angular frequencies [rad/s], 1-D, finite, >= 0, strictly increasing.
    :param S: spectral density [m^2 s/rad], same length, finite, >= 0.
    """
    return 4.0 * math.sqrt(spectral_moment(omega, S, 0))


def _parabola_vertex(x: np.ndarray, y: np.ndarray) -> float:
    """Abscissa of the vertex of the parabola through three points, clipped to [x0, x2]."""
    (x0, x1, x2), (y0, y1, y2) = x, y
    denom = (x0 - x1) * (x0 - x2) * (x1 - x2)
    a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / denom
    b = (x2**2 * (y0 - y1) + x1**2 * (y2 - y0) + x0**2 * (y1 - y2)) / denom
    if a >= 0.0:  # flat top: no interior maximum, keep the sample
        return float(x1)
    return float(np.clip(-b / (2.0 * a), x0, x2))


def peak_frequency(omega: ArrayLike, S: ArrayLike) -> float:
    """Peak angular frequency [rad/s]: argmax refined by a parabola through its neighbours.

    :param omega: angular frequencies [rad/s], 1-D, finite, >= 0, strictly increasing.
    :param S: spectral density [m^2 s/rad], same length, finite, >= 0, not all zero.
    """
    w, s = _spectrum_arrays("omega", omega, "S", S, allow_zero=True)
    i = int(np.argmax(s))
    if s[i] <= 0.0:
        raise ValueError("S is zero everywhere: the peak frequency is undefined")
    if 0 < i < w.size - 1:
        return _parabola_vertex(w[i - 1 : i + 2], s[i - 1 : i + 2])
    return float(w[i])


# --------------------------------------------------------------------------- measured spectra


@dataclass(frozen=True, eq=False)
class MeasuredSpectrum:
    """A sampled spectrum, linearly interpolated between samples and zero outside them.

    :param omega: angular frequencies [rad/s], 1-D, finite, > 0, strictly increasing.
    :param density: spectral density [m^2 s/rad], same length, finite, >= 0.
    """

    omega: np.ndarray
    density: np.ndarray

    def __post_init__(self) -> None:
        w, s = _spectrum_arrays("omega", self.omega, "density", self.density)
        # Private read-only copies so the frozen object cannot be mutated through its arrays.
        for name, arr in (("omega", w), ("density", s)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @classmethod
    def from_hz(cls, frequency_hz: ArrayLike, density_m2_per_hz: ArrayLike) -> MeasuredSpectrum:
        """Build from a spectrum per Hz: ``omega = 2 pi f``, ``S(omega) = S(f) / (2 pi)``.

        :param frequency_hz: frequencies [Hz], 1-D, finite, > 0, strictly increasing.
        :param density_m2_per_hz: spectral density [m^2/Hz], same length, finite, >= 0.
        """
        f, s = _spectrum_arrays(
            "frequency_hz", frequency_hz, "density_m2_per_hz", density_m2_per_hz
        )
        return cls(2.0 * np.pi * f, s / (2.0 * np.pi))

    def __call__(self, omega: ArrayLike) -> np.ndarray:
        """Density [m^2 s/rad] at ``omega`` [rad/s] (any shape); 0 outside the measured range."""
        w = _finite_array("omega", omega)
        return np.interp(w, self.omega, self.density, left=0.0, right=0.0)

    @property
    def hs(self) -> float:
        """Significant wave height 4 sqrt(m0) over the measured band [m]."""
        return significant_wave_height(self.omega, self.density)

    @property
    def peak_frequency(self) -> float:
        """Peak angular frequency [rad/s] (parabolic refinement)."""
        return peak_frequency(self.omega, self.density)


# --------------------------------------------------------------------------- NDBC files


def ndbc_example_path() -> Path:
    """Path of the shipped excerpt: NDBC buoy 46042, 1996-01-01 00:00 to 01-07 23:00, hourly."""
    return Path(str(files("marine_envs") / "data" / NDBC_EXAMPLE))


@dataclass(frozen=True, eq=False)
class NDBCSpectra:
    """Hourly non-directional spectra of an NDBC ``swden`` file.

    :param times: record times, numpy ``datetime64[m]`` (UTC), shape (n_times,).
    :param frequency_hz: band centre frequencies [Hz], shape (n_freq,).
    :param density_hz: spectral density [m^2/Hz], shape (n_times, n_freq); NaN where missing.
    """

    times: np.ndarray
    frequency_hz: np.ndarray
    density_hz: np.ndarray

    def __post_init__(self) -> None:
        n_t, n_f = len(self.times), len(self.frequency_hz)
        if np.shape(self.density_hz) != (n_t, n_f):
            raise ValueError(
                f"density_hz has shape {np.shape(self.density_hz)}: must be ({n_t}, {n_f})"
            )

    def __len__(self) -> int:
        return len(self.times)

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask of the records without missing values, shape (n_times,)."""
        return np.all(np.isfinite(self.density_hz), axis=1)

    def spectrum(self, i: int) -> MeasuredSpectrum:
        """Record ``i`` as a :class:`MeasuredSpectrum` in rad/s units (m^2 s/rad).

        :param i: record index (negative counts from the end).
        """
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"i={i} is out of range for {n} records")
        row = self.density_hz[i]
        if not np.all(np.isfinite(row)):
            raise ValueError(
                f"record i={i} at {self.times[i]} has missing values (NDBC codes 99/999)"
            )
        return MeasuredSpectrum.from_hz(self.frequency_hz, row)


def _read_lines(path: Path) -> list[str]:
    """Lines of a text file, gunzipped transparently (by magic bytes, not by suffix)."""
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        raw = gzip.decompress(raw)
    return raw.decode("ascii", errors="replace").splitlines()


def _parse_header(line: str, path: Path) -> tuple[int, np.ndarray]:
    """Number of time columns (4 or 5) and the frequencies [Hz] of an NDBC header line."""
    tokens = line.lstrip("#").split()
    labels = [t.upper() for t in tokens[:5]]
    if labels[:4] not in (["YY", "MM", "DD", "HH"], ["YYYY", "MM", "DD", "HH"]):
        raise ValueError(f"{path}: line 1 is not an NDBC header 'YY MM DD hh ...': {line!r}")
    n_time = 5 if len(labels) == 5 and labels[4] == "MM" else 4
    try:
        freqs = np.array([float(t) for t in tokens[n_time:]])
    except ValueError:
        raise ValueError(f"{path}: line 1 has a non-numeric frequency: {line!r}") from None
    if freqs.size == 0 or np.any(freqs <= 0) or np.any(np.diff(freqs) <= 0):
        raise ValueError(f"{path}: line 1 frequencies must be > 0 and strictly increasing")
    return n_time, freqs


def _parse_time(fields: list[str], n_time: int) -> np.datetime64:
    """Record time from the YY/YYYY MM DD hh [mm] columns (2-digit years: >= 50 is 19xx)."""
    year, month, day, hour = (int(f) for f in fields[:4])
    minute = int(fields[4]) if n_time == 5 else 0
    if year < 100:
        year += 1900 if year >= 50 else 2000
    return np.datetime64(f"{year:04d}-{month:02d}-{day:02d}T{hour:02d}:{minute:02d}", "m")


def read_ndbc_spectra(path: str | Path) -> NDBCSpectra:
    """Read an NDBC spectral wave density file (``*swden.txt`` or ``.txt.gz``).

    Header forms: ``YY MM DD hh f1 f2 ...`` or ``#YY``/``YYYY MM DD hh mm f1 ...`` with the
    frequencies in Hz; values are m^2/Hz. Missing-value codes (99.00, or 999.00 and above)
    become NaN. Further lines starting with ``#`` (unit lines) and blank lines are skipped.

    :param path: file path; gzip-compressed files are opened transparently.
    :return: the records as :class:`NDBCSpectra`.
    """
    path = Path(path)
    lines = _read_lines(path)
    if not lines:
        raise ValueError(f"{path}: file is empty")
    n_time, freqs = _parse_header(lines[0], path)
    n_cols = n_time + freqs.size
    times, rows = [], []
    for lineno, line in enumerate(lines[1:], start=2):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = line.split()
        if len(fields) != n_cols:
            raise ValueError(f"{path}: line {lineno} has {len(fields)} values, header has {n_cols}")
        try:
            times.append(_parse_time(fields, n_time))
            rows.append([float(v) for v in fields[n_time:]])
        except ValueError as err:
            raise ValueError(f"{path}: line {lineno} is malformed: {err}") from None
    if not rows:
        raise ValueError(f"{path}: no data records after the header")
    density = np.array(rows)
    # NDBC fills missing bands with 99.00 or 999.00 (and 9999.0 in some products).
    missing = np.isclose(density, 99.0) | (density >= 999.0)
    density[missing] = np.nan
    return NDBCSpectra(np.array(times, dtype="datetime64[m]"), freqs, density)


# --------------------------------------------------------------------------- fitting

_FIT_KINDS = ("pm", "jonswap")
_GAMMA_STARTS = (1.5, 3.3, 7.0)  # several starts: the gamma direction has shallow minima


@dataclass(frozen=True)
class SpectrumFit:
    """A PM or JONSWAP spectrum fitted to a sampled spectrum.

    :param kind: ``"pm"`` or ``"jonswap"``.
    :param hs: significant wave height of the fitted spectrum [m].
    :param tp: peak period [s].
    :param gamma: peak enhancement factor [-] (1.0 for PM).
    :param rms_residual: RMS of fitted minus measured density [m^2 s/rad].
    :param relative_residual: ``rms_residual`` divided by the RMS of the measured density [-].
    """

    kind: str
    hs: float
    tp: float
    gamma: float
    rms_residual: float
    relative_residual: float

    def __post_init__(self) -> None:
        if self.kind not in _FIT_KINDS:
            raise ValueError(f"kind={self.kind!r} is invalid: must be one of {_FIT_KINDS}")

    def __call__(self, omega: ArrayLike) -> np.ndarray:
        """Fitted density [m^2 s/rad] at ``omega`` [rad/s] (any shape)."""
        if self.kind == "pm":
            return pierson_moskowitz(omega, self.hs, self.tp)
        return jonswap(omega, self.hs, self.tp, self.gamma)


def _model(kind: str, omega: np.ndarray, params: np.ndarray) -> np.ndarray:
    if kind == "pm":
        return pierson_moskowitz(omega, params[0], params[1])
    return jonswap(omega, params[0], params[1], params[2])


def _least_squares(kind: str, w: np.ndarray, s: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Fit on the linear density scaled by its maximum, so the peak dominates the cost."""
    from scipy.optimize import least_squares  # (here, not at import: it takes 0.2 s)

    scale = float(s.max())

    def residual(p: np.ndarray) -> np.ndarray:
        return (_model(kind, w, p) - s) / scale

    n = x0.size
    lower = np.r_[1e-6, 1e-6, 1.0][:n]
    upper = np.r_[np.inf, np.inf, 10.0][:n]
    return least_squares(residual, x0, bounds=(lower, upper), x_scale="jac").x


def fit_spectrum(
    omega: ArrayLike | MeasuredSpectrum, S: ArrayLike | None = None, kind: str = "pm"
) -> SpectrumFit:
    """Least-squares fit of a PM or JONSWAP spectrum to a sampled spectrum.

    The start comes from the moments (hs = 4 sqrt(m0), tp = 2 pi / peak frequency); JONSWAP
    is started from several gammas and the best fit kept. Bounds: hs > 0, tp > 0,
    1 <= gamma <= 10.

    :param omega: angular frequencies [rad/s] (1-D, >= 0, increasing), or a MeasuredSpectrum.
    :param S: spectral density [m^2 s/rad]; omit it when ``omega`` is a MeasuredSpectrum.
    :param kind: ``"pm"`` or ``"jonswap"``.
    :return: the fit as :class:`SpectrumFit`.
    """
    if kind not in _FIT_KINDS:
        raise ValueError(f"kind={kind!r} is invalid: must be one of {_FIT_KINDS}")
    if isinstance(omega, MeasuredSpectrum):
        if S is not None:
            raise ValueError(
                f"S={S!r} is invalid: omit S when omega is a MeasuredSpectrum (pass kind=...)"
            )
        w, s = omega.omega, omega.density
    elif S is None:
        raise ValueError("S=None is invalid: give S with omega, or a MeasuredSpectrum")
    else:
        w, s = _spectrum_arrays("omega", omega, "S", S, min_points=3, allow_zero=True)
    if s.max() <= 0.0:
        raise ValueError("S is zero everywhere: there is no spectrum to fit")
    hs0 = significant_wave_height(w, s)
    wp0 = peak_frequency(w, s)
    if wp0 <= 0.0:
        raise ValueError("S peaks at omega=0: no PM/JONSWAP start can be taken from it")
    tp0 = 2.0 * math.pi / wp0
    starts = (
        [np.array([hs0, tp0])] if kind == "pm" else [np.array([hs0, tp0, g]) for g in _GAMMA_STARTS]
    )
    fits = [_least_squares(kind, w, s, x0) for x0 in starts]
    rms = [float(np.sqrt(np.mean((_model(kind, w, p) - s) ** 2))) for p in fits]
    best = int(np.argmin(rms))
    p = fits[best]
    return SpectrumFit(
        kind=kind,
        hs=float(p[0]),
        tp=float(p[1]),
        gamma=float(p[2]) if kind == "jonswap" else 1.0,
        rms_residual=rms[best],
        relative_residual=rms[best] / float(np.sqrt(np.mean(s**2))),
    )
