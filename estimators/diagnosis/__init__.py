"""Mismatch diagnosis: why a simulation and a recording disagree.

:func:`diagnose` locates the mismatch (channels, windows, band), names the physics the model left
out as entries of the effect catalogue (:mod:`marine_envs.models.effects`), fits them with
uncertainty and shows the improvement on held-out data. The package, bottom up:

* :mod:`.innovations` - the nominal filter's whitened innovations and their sensitivities;
* :mod:`.residuals` - the nominal smoother, equation errors and the sea's noise model;
* :mod:`.hypotheses` - every catalogue entry as a family of candidate terms fitted to them;
* :mod:`.selection` - cross-validated, significance-tested selection of the families;
* :mod:`.rollout` - multi-step predictions with and without the findings;
* :mod:`.explain` - a finding in a naval architect's words;
* :mod:`.api` - :func:`diagnose`, the checks of its inputs, :class:`Diagnosis` and its JSON;
* :mod:`.report` - the Markdown report with figures;
* :mod:`.synthetic` - closed-loop recordings of any model with effects added;
* :mod:`.cases` - the seeded acceptance set and how a diagnosis is scored on it.
"""

from .api import Diagnosis, Finding, check, diagnose, read_params
from .selection import DiagnosisConfig
from .synthetic import synthesize, typical_effect

__all__ = ["Diagnosis", "DiagnosisConfig", "Finding", "check", "diagnose", "read_params",
           "synthesize", "typical_effect"]
