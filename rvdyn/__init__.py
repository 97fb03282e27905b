"""rvdyn: quasi-static meshing analysis of the RV reducer: transmission error, statistics, backlash,
and the hysteresis curve with the datasheet figures (rvdyn.stiffness).

Two contact providers behind one solver: ``analytic`` (exact envelope and involute distances)
and ``fcl`` (python-fcl distance queries on the exported meshes).

* :func:`solve` -- one case (an :class:`rvcad.Case`, a dict or a JSON path) -> ``.table``,
  ``.stats``, ``.plot()`` (:mod:`rvdyn.api`).
* :func:`run_cases` / :class:`Runner` -- many cases through a content-keyed disk cache, in this
  process, a local process pool or a Dask cluster (:mod:`rvdyn.runner`, :mod:`rvdyn.cache`).
* :func:`run_te`, :func:`te_stats`, :func:`backlash` -- the building blocks (:mod:`rvdyn.te`).
* :func:`te_jacobian` -- the TE's derivatives along directions in case space at converged states, by implicit
  differentiation of the equilibrium (:mod:`rvdyn.implicit`).
* :func:`hysteresis` -- the maker's torque sweep and datasheet figures (:mod:`rvdyn.stiffness`);
  contact laws ``impact`` and ``physical`` (:mod:`rvdyn.options`, :mod:`rvdyn.materials`,
  :mod:`rvdyn.bearings`).
"""
from rvdyn.api import Result, solve
from rvdyn.cache import CaseCache, Job
from rvdyn.contacts import AnalyticContacts, ContactLaw
from rvdyn.implicit import JacobianResult, te_jacobian
from rvdyn.runner import Runner, run_cases
from rvdyn.solver import ARCSEC_PER_RAD, InterferenceError, QuasiStaticSolver, Solution
from rvdyn.stiffness import StiffnessResult, hysteresis
from rvdyn.te import TEResult, backlash, run_te, te_stats, write_table_atomic

__all__ = ["ARCSEC_PER_RAD", "AnalyticContacts", "CaseCache", "ContactLaw", "InterferenceError", "JacobianResult",
           "Job", "QuasiStaticSolver", "Result", "Runner", "Solution", "StiffnessResult", "TEResult", "backlash", "hysteresis", "run_cases", "run_te",
           "solve", "te_jacobian", "te_stats", "write_table_atomic"]
