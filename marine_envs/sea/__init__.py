"""The sea: wave spectra (PM, JONSWAP, measured), sea states that may vary in time, wave
realisations that step cheaply and reproducibly, and the coupling of waves to each model's
disturbance inputs. Units: SI, angular frequency in rad/s, spectral density in m^2 s/rad."""

from .coupling import USVWaveCoupling, wave_coupling
from .spectra import (
    MeasuredSpectrum,
    NDBCSpectra,
    SpectrumFit,
    fit_spectrum,
    jonswap,
    ndbc_example_path,
    peak_frequency,
    pierson_moskowitz,
    read_ndbc_spectra,
    significant_wave_height,
    spectral_moment,
)
from .waves import (
    Schedule,
    SeaState,
    WaveRealisation,
    elevation_coupling,
    encounter_frequency,
    energy_band,
)

__all__ = [
    "MeasuredSpectrum", "NDBCSpectra", "Schedule", "SeaState", "SpectrumFit", "USVWaveCoupling",
    "WaveRealisation", "elevation_coupling", "encounter_frequency", "energy_band", "fit_spectrum",
    "jonswap", "ndbc_example_path", "peak_frequency", "pierson_moskowitz", "read_ndbc_spectra",
    "significant_wave_height", "spectral_moment", "wave_coupling",
]
