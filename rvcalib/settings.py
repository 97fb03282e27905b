"""The loop's settings: one frozen object, validated in one place, echoed into the result."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from rvcalib.library import FAMILIES
from rvcalib.sparse import SparseSettings

CONTACTS = (None, "physical", "impact")
#: The estimators: the sum of single effects with its loop (rvcalib.sparse, rvcalib.loop), or the Gaussian
#: posterior of every candidate at its tolerance class (rvcalib.gaussian).
ESTIMATORS = ("sparse", "tolerance-prior")
#: The most linearisations a search may be given.
MAX_LINEARISATIONS = 100


@dataclass(frozen=True)
class CalibrationSettings:
    """What :func:`rvcalib.loop.calibrate` does, with its defaults.

    Attributes
    ----------
    max_effects : int
        Most single effects the estimator may use (L of :mod:`rvcalib.sparse`). A cap, not a choice: the data
        choose how many are supported; the result says when every one was used (the cap binds).
    coverage : float
        Level of the credible sets and of the intervals (0.95).
    min_purity : float
        Smallest correlation of the fitted signals of a credible set's members for the set to be reported.
    empirical_weight : float
        Prior weight of the whole empirical block, in units of one physical type's weight.
    max_order : int or None
        Highest harmonic order of the empirical block (default: the highest the sparsest run's readings resolve).
    max_linearisations : int
        Most linearisations of the reducer model (the estimator is re-run at each).
    step_tolerance : float
        The iteration has converged when the last linearisation's step changes the model TE by at most this
        fraction of the noise (RMS over the readings).
    swaps : int
        Most swaps of the chosen set (one feature out, another in: :mod:`rvcalib.swaps`) tried through the reducer
        model at a linearisation where the estimator's proposals do not lower the criterion; 0: none.
    workers : int
        Processes for the Jacobian's columns.
    contact : str or None
        The contact law of the reducer model: None (each case's, rvdyn's default: physical), physical or impact.
    rated_Nm : float or None
        Rated torque of the reducer for its datasheet (N m); None: no datasheet is computed for a design other
        than the default.
    samples_per_rev : int or None
        Readings per output revolution ``rv-calibrate`` fits (:func:`rvcalib.cli.run` averages denser runs down,
        :func:`rvrig.average.averaged`): None, the density whose averaging filter is flat to the reducer model's
        orders (:func:`rvrig.average.model_samples_per_rev`); 0, every reading.
    families : tuple of str
        Candidate families in the library.
    estimator : str
        ``sparse``: the sum of single effects, its chosen set refined through the reducer model, re-linearised
        (:mod:`rvcalib.sparse`); ``tolerance-prior``: every candidate a Gaussian random effect at its tolerance
        class, their joint maximum a posteriori through the reducer model and its Laplace posterior, no selection
        (:mod:`rvcalib.gaussian`). ``max_effects``, ``min_purity``, ``max_linearisations``, ``step_tolerance`` and
        ``swaps`` are the sparse estimator's.
    secant_width : float
        Half-width of the secant column of a pin-wise or kinked candidate the posterior has not chosen, in prior
        scales (:mod:`rvcalib.reducer_model`): the statistical linearisation over the values the candidate may
        have. 1: over its tolerance class. sqrt(3) is the unscented transform's sigma point of one Gaussian
        parameter (``n + kappa = 3``; S. J. Julier, J. K. Uhlmann, Proc. SPIE 3068, 1997): the secant then keeps
        the prior's fourth moment too and sees a response that bends within a few classes further out; it changes
        other results as well (docs/calibration.md, section 9).
    half_turn : bool
        The tolerance-prior estimator's second search, from the half-turn image of its first end, and its one answer
        over both ends (:mod:`rvcalib.arrangements`); no effect where no crank stands half a turn from another.
    """

    max_effects: int = 30
    coverage: float = 0.95
    min_purity: float = 0.5
    empirical_weight: float = 1.0
    max_order: int | None = None
    max_linearisations: int = 12
    step_tolerance: float = 0.1
    swaps: int = 1
    workers: int = 1
    contact: str | None = None
    rated_Nm: float | None = None
    samples_per_rev: int | None = None
    families: tuple = FAMILIES
    estimator: str = "sparse"
    half_turn: bool = True
    secant_width: float = 1.0

    def validate(self) -> "CalibrationSettings":
        """Return self, or raise ValueError naming the field, its value and what is allowed."""
        self.sparse().validate()

        def bad(name: str, allowed: str) -> None:
            raise ValueError(f"settings.{name} = {getattr(self, name)!r} is not allowed: {allowed}")

        if not (math.isfinite(self.empirical_weight) and self.empirical_weight > 0):
            bad("empirical_weight", "a finite number > 0")
        if self.max_order is not None and not (isinstance(self.max_order, int) and 1 <= self.max_order <= 5000):
            bad("max_order", "None or an integer in 1..5000")
        if not (isinstance(self.max_linearisations, int) and 1 <= self.max_linearisations <= MAX_LINEARISATIONS):
            bad("max_linearisations", f"an integer in 1..{MAX_LINEARISATIONS}")
        if not (math.isfinite(self.step_tolerance) and self.step_tolerance > 0):
            bad("step_tolerance", "a finite number > 0")
        if not (isinstance(self.swaps, int) and 0 <= self.swaps <= 20):
            bad("swaps", "an integer in 0..20")
        if not (isinstance(self.workers, int) and 1 <= self.workers <= 64):
            bad("workers", "an integer in 1..64")
        if self.contact not in CONTACTS:
            bad("contact", f"one of {list(CONTACTS)}")
        if self.rated_Nm is not None and not (math.isfinite(self.rated_Nm) and 0 < self.rated_Nm <= 20000):
            bad("rated_Nm", "None or a number in (0, 20000] N m")
        k = self.samples_per_rev
        if k is not None and not (isinstance(k, int) and not isinstance(k, bool) and (k == 0 or 16 <= k <= 100000)):
            bad("samples_per_rev", "None, 0 (every reading) or an integer in 16..100000")
        if not self.families or any(f not in FAMILIES for f in self.families):
            bad("families", f"a non-empty tuple from {list(FAMILIES)}")
        if self.estimator not in ESTIMATORS:
            bad("estimator", f"one of {list(ESTIMATORS)}")
        if not (isinstance(self.secant_width, (int, float)) and not isinstance(self.secant_width, bool)
                and 0.1 <= self.secant_width <= 10.0):
            bad("secant_width", "a number in [0.1, 10] prior scales")
        if not isinstance(self.half_turn, bool):
            bad("half_turn", "True or False")
        return self

    def sparse(self) -> SparseSettings:
        """The estimator's part of the settings."""
        return SparseSettings(max_effects=self.max_effects, coverage=self.coverage, min_purity=self.min_purity)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["families"] = list(self.families)
        return d
