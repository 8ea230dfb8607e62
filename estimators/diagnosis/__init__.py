"""Mismatch diagnosis: why a simulation and a recording disagree.

:func:`diagnose` locates the mismatch (channels, windows, band), names the physics the model left
out as entries of the effect catalogue (:mod:`marine_envs.models.effects`), fits them with
uncertainty and shows the improvement on held-out data. The package, bottom up; records in a
seaway, judged by the nominal filter's innovations:

* :mod:`.innovations` - the nominal filter's whitened innovations and their sensitivities;
* :mod:`.residuals` - the nominal smoother, equation errors and the sea's noise model;
* :mod:`.changes` - changes in mid-record detected and dated on the innovations;
* :mod:`.hypotheses` - every catalogue entry as a family of candidate terms fitted to them;
* :mod:`.selection` - cross-validated, significance-tested selection of the families;
* :mod:`.rollout` - multi-step predictions with and without the findings;
* :mod:`.feedback` - whether an input effect holds on the input the controller did not choose;
* :mod:`.actuators` - input effects read off an actuator position sensor, command against position;
* :mod:`.seaway` - the diagnosis of a record in a seaway: checks, smoothing, search, validation;
* :mod:`.sizing` - its sample step checked, its rate and length bounded (memory) before the work;

model tests (decays, zigzags, lab runs, series of them), judged in free simulation:

* :mod:`.modes` - a free decay's frequency, damping and extinction curve against the model's modes;
* :mod:`.output_error` - recordings on the model's bandwidth, batched free simulations, fits;
* :mod:`.comparison` - nested models refitted whole and compared on held-out data;
* :mod:`.spread` - the coefficients' spread between records, validation across amplitude classes;
* :mod:`.ranges` - a finding's fitted range, non-physical signs, the offset a constant force is;
* :mod:`.self_calibration` - records the model cannot follow whole: windows, parameters chosen;
* :mod:`.validation` - a diagnosis's models predicting other tests (``marine validate``);
* :mod:`.free_simulation` - the diagnosis of a series; :mod:`.free_simulation_report` and
  :mod:`.free_simulation_figures` its report;

and for both:

* :mod:`.explain` - a finding in a naval architect's words;
* :mod:`.result` - :class:`Diagnosis`, its findings, its JSON and summary;
* :mod:`.api` - :func:`diagnose`: the checks of its inputs, and which way a record is judged;
* :mod:`.report` - the Markdown report with figures (:mod:`.report_format`: what both share);
* :mod:`.synthetic` - closed-loop recordings of any model with effects added;
* :mod:`.cases` - the seeded acceptance set and how a diagnosis is scored on it;
* :mod:`.scenarios` - cases drawn fresh from a seed: vehicle, effect, sea, sensors, generator.
"""

from .api import check, diagnose, read_params
from .result import Diagnosis, Finding
from .selection import DiagnosisConfig
from .synthetic import synthesize, typical_effect

__all__ = ["Diagnosis", "DiagnosisConfig", "Finding", "check", "diagnose", "read_params",
           "synthesize", "typical_effect"]
