"""Response surface methodology for the RV-reducer transmission-error study.

Designs (:mod:`rsm.design`), coded/actual units (:mod:`rsm.coding`), least-squares fit with
the paper's ANOVA (:mod:`rsm.model`, :mod:`rsm.results`), model reduction
(:mod:`rsm.reduce`), augmenting a model with supported higher-order or physical terms
(:mod:`rsm.augment`, candidates in :mod:`rsm.candidates`), surface analysis and validation (:mod:`rsm.surface`), figures
(:mod:`rsm.plots`) and the ``rsm`` command line (:mod:`rsm.cli`).

Quick start
-----------
>>> import pandas as pd, rsm
>>> data = pd.read_csv("paper_table6_bbd_runs.csv")                       # doctest: +SKIP
>>> res = rsm.fit(data, ["EA", "EB", "EC", "ED"], "te_arcmin",
...               levels="paper_table5_levels.csv")                       # doctest: +SKIP
>>> res.anova                     # Table 7                               # doctest: +SKIP
>>> res.params_actual             # Eq. 8                                 # doctest: +SKIP
>>> rsm.paper_reduction(res).coefficients   # Eq. 9                       # doctest: +SKIP
>>> res.predict({"EA": [0.5], "EB": [0], "EC": [0], "ED": [0]})          # doctest: +SKIP
>>> rsm.augment(res).added        # lack of fit -> ['EB^2:EC']            # doctest: +SKIP

Term syntax for user-chosen models: see :mod:`rsm.terms` (``EA``, ``EA:EB``, ``EA^2``,
``EA^3``, ``EA:EB:EC``, presets ``linear``/``2fi``/``quadratic``).
"""

from .augment import AugmentResult, SelectionRule, TermTest, augment, fit_block, format_augment
from .candidates import CandidateTerm, DerivedColumn, default_candidates, polynomial_candidates
from .checks import NotEstimableError, check_numeric_column
from .coding import FactorLevels, Levels
from .design import Design, box_behnken, central_composite, full_factorial_3, make_design
from .model import ResponseSurfaceModel, ZeroPureErrorWarning, fit
from .reduce import (
    BackwardResult,
    PaperReduction,
    ReductionComparison,
    backward_elimination,
    compare_reductions,
    paper_reduction,
    reduce_model,
)
from .results import RSMResults
from .surface import (
    CanonicalAnalysis,
    Optimum,
    PolynomialSurface,
    ValidationResult,
    validation_metrics,
)
from .terms import parse_terms, term_name

__all__ = [
    "AugmentResult", "SelectionRule", "TermTest", "augment", "fit_block", "format_augment",
    "CandidateTerm", "DerivedColumn", "default_candidates", "polynomial_candidates",
    "NotEstimableError", "check_numeric_column", "FactorLevels", "Levels",
    "Design", "box_behnken", "central_composite", "full_factorial_3", "make_design",
    "ResponseSurfaceModel", "RSMResults", "ZeroPureErrorWarning", "fit",
    "BackwardResult", "PaperReduction", "ReductionComparison", "backward_elimination",
    "compare_reductions", "paper_reduction", "reduce_model",
    "CanonicalAnalysis", "Optimum", "PolynomialSurface", "ValidationResult",
    "validation_metrics", "parse_terms", "term_name",
]
