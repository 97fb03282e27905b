"""rvdyn: quasi-static meshing analysis of the RV reducer: transmission error, statistics, backlash,
and the hysteresis curve with the datasheet figures (rvdyn.stiffness).

Two contact providers behind one solver: ``analytic`` (exact envelope and involute distances)
and ``fcl`` (python-fcl distance queries on the exported meshes).
"""
from rvdyn.contacts import AnalyticContacts, ContactLaw
from rvdyn.solver import ARCSEC_PER_RAD, InterferenceError, QuasiStaticSolver, Solution
from rvdyn.te import TEResult, backlash, run_te, te_stats, write_table_atomic

__all__ = ["ARCSEC_PER_RAD", "AnalyticContacts", "ContactLaw", "InterferenceError", "QuasiStaticSolver", "Solution",
           "TEResult", "backlash", "run_te", "te_stats", "write_table_atomic"]
