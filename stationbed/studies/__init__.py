"""Studies on top of runs: the cross-formulation check, work-precision and stability.

``check``
    Every formulation of a scene against each other (:mod:`.check`).
``precision_study``
    Every formulation x integrator x setting on one scene against a reference solution:
    CSV + PNG + a table of the cheapest method reaching 1e-3, 1e-6 and 1e-9 rad
    (:mod:`.precision`).
``stability_study``
    Seven cases where methods fail, each with a detector, a verdict per method, a CSV and a
    PNG (:mod:`.stability`, one module per case).

Shared pieces: :mod:`.common` (the error, the methods swept, a guarded run, CSV files),
:mod:`.probes` (measurements on runs and on the compiled system), :mod:`.plotting`
(matplotlib, extra ``plot``, imported only when a chart is drawn, on the Agg backend).
"""

from .common import StudyError
from .precision import PrecisionResult, precision_study
from .stability import STABILITY_CASES, Case, stability_study

__all__ = ["StudyError", "precision_study", "stability_study", "STABILITY_CASES", "PrecisionResult", "Case"]
