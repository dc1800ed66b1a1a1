"""Model-mismatch diagnosis: where a model and a recording differ, which physics is missing,
whether it is identified by the data, and whether the improvement holds on held-out data.

Public API::

    diagnose_recording(recording, scenario=None, *, free=None, exclude=(), folds="auto",
                       n_folds=5, cv_report=()) -> Diagnosis
                                                    # lightcurve HDF5, CSV, or CSS recording HDF5
    diagnose_css_recording(path, configuration=None) -> Diagnosis
    diagnose(problem, ...) -> Diagnosis             # on a Problem built below
    load_problem(recording, scenario=None, free=None) -> (Problem, skip, options, notes)
    magnitude_problem(lightcurve, shape, ...) / css_problem(css_ctx, y, sigma) -> Problem
    css_recording_problem(path) -> (Problem, notes) # model from a CSS recording's own data
    make_folds(problem, by="auto", k=5) -> (Folds | None, reason)
    write_report(diagnosis, out_dir) -> (diagnosis.json, report.html)
    apply_fit(fit_json, recording, scenario=None) -> Transfer   # diagnose --apply
    write_transfer_report(transfer, out_dir) -> (transfer.json, transfer.html)

Modules: :mod:`.problem` (data + baseline model + free parameters), :mod:`.baseline`
(least-squares fits, ΔBIC), :mod:`.residuals` (whiteness, χ² band, segments),
:mod:`.candidates` (fitting every registered effect), :mod:`.surface` (the surface refit
candidate), :mod:`.folds` (blocked cross-validation folds), :mod:`.selection` (held-out
predictions and gain), :mod:`.identify` (are the parameters identified?), :mod:`.diagnose`
(orchestration), :mod:`.report` (JSON + self-contained HTML), :mod:`.transfer` (apply a
fitted model to new recordings), :mod:`.fast` (cached Earthshine, fine self-shadowing),
:mod:`.css_recording` (the CSS model from a recording file).
"""

from .css_recording import css_recording_problem
from .diagnose import Diagnosis, diagnose, diagnose_css_recording, diagnose_recording, load_problem
from .folds import Folds, make_folds
from .problem import Problem, css_problem, magnitude_problem
from .report import write_report
from .transfer import Transfer, apply_fit, write_transfer_report

__all__ = ["Diagnosis", "Problem", "Folds", "Transfer", "diagnose", "diagnose_recording",
           "load_problem", "magnitude_problem", "css_problem", "write_report",
           "diagnose_css_recording", "css_recording_problem", "make_folds", "apply_fit",
           "write_transfer_report"]
