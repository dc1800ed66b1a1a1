"""Model-mismatch diagnosis (issue 10): where a model and a recording differ, which physics
effect is missing, its fitted parameters, and the improvement.

Public API::

    diagnose_recording(recording, scenario=None, *, free=None, exclude=()) -> Diagnosis
                                                    # lightcurve HDF5, CSV, or CSS recording HDF5
    diagnose_css_recording(path, configuration=None) -> Diagnosis
    css_recording_problem(path) -> (Problem, notes) # model from a CSS recording's own data
    diagnose(problem, ...) -> Diagnosis             # on a Problem built below
    magnitude_problem(lightcurve, shape, ...) / css_problem(css_ctx, y, sigma) -> Problem
    write_report(diagnosis, out_dir) -> (diagnosis.json, report.html)
    cross_validate(problem, fit) -> dict            # leave-one-night-out

Modules: :mod:`.problem` (data + baseline model + free parameters), :mod:`.baseline`
(least-squares fits, ΔBIC), :mod:`.residuals` (whiteness, χ² band, segments),
:mod:`.candidates` (scoring every registered effect), :mod:`.diagnose` (orchestration),
:mod:`.report` (JSON + self-contained HTML), :mod:`.fast` (cached Earthshine, fine
self-shadowing), :mod:`.css_recording` (the CSS model from a recording file).
"""

from .css_recording import css_recording_problem
from .diagnose import (Diagnosis, cross_validate, diagnose, diagnose_css_recording,
                       diagnose_recording)
from .problem import Problem, css_problem, magnitude_problem
from .report import write_report

__all__ = ["Diagnosis", "Problem", "diagnose", "diagnose_recording", "cross_validate",
           "magnitude_problem", "css_problem", "write_report", "diagnose_css_recording",
           "css_recording_problem"]
