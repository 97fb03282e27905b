"""The short Python API: ``rvdyn.solve(case)`` -> a result with ``.table``, ``.stats`` and ``.plot()``.

>>> import rvdyn
>>> res = rvdyn.solve({"errors": {"pin_pitch": 0.02}}, steps=360)   # doctest: +SKIP
>>> res.stats["pp"], res.table[["input_deg", "te_arcsec"]]           # doctest: +SKIP
>>> res.plot()                                                       # doctest: +SKIP

A thin layer over :func:`rvdyn.te.run_te` (the solve) and :func:`rvdyn.te.te_stats` (the
statistics). matplotlib is imported only inside :meth:`Result.plot`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rvcad.errors import Case, load_case
from rvdyn.contacts import ContactLaw
from rvdyn.te import TEResult, run_te


@dataclass
class Result(TEResult):
    """TE of one case: :class:`rvdyn.te.TEResult` with a plot.

    Attributes
    ----------
    case : Case
    solver : str
    table : pandas.DataFrame
        ``input_deg, output_deg, te_arcsec, contacts, peak_force_N``, one row per step in the order
        of motion; TE = theta_out - theta_in / ratio in arcsec, positive when the output leads.
    stats : dict
        ``pp, mean, mean_abs, rms`` (arcsec, :func:`rvdyn.te.te_stats`), ``ratio``, ``seconds``,
        ``steps``, ``revolutions``, ``direction``, ``load_Nm``, ``solver``.
    """

    def plot(self, ax: Any = None, path: str | Path | None = None) -> Any:
        """TE (arcsec) against the output angle (deg).

        Parameters
        ----------
        ax : matplotlib Axes or None
            Axes to draw on; None: a new pyplot figure (shown inline in a notebook).
        path : str, Path or None
            Also save the figure there (written atomically).

        Returns
        -------
        matplotlib Axes
        """
        if ax is None:
            import matplotlib.pyplot as plt

            _, ax = plt.subplots(figsize=(8, 4))
        t = self.table
        ax.plot(t["output_deg"], t["te_arcsec"], lw=1.0)
        ax.set_xlabel("output angle [deg]")
        ax.set_ylabel("TE [arcsec]")
        s = self.stats
        ax.set_title(f"{self.case.name}: {self.solver}, {s.get('load_Nm', float('nan')):g} N m; "
                     f"pp {s['pp']:.3f} arcsec, mean |TE| {s['mean_abs']:.3f} arcsec")
        ax.grid(True, lw=0.3)
        if path is not None:
            from rvcad.atomic import atomic_path

            path = Path(path)
            with atomic_path(path, suffix=path.suffix) as tmp:
                ax.figure.savefig(tmp, dpi=110)
        return ax


def as_case(case: Case | dict[str, Any] | str | Path | None) -> Case:
    """A :class:`rvcad.Case` from a case, a case dict (conventions' case JSON) or a path to a case JSON.

    None gives the nominal case with no errors.
    """
    if case is None or isinstance(case, (str, Path)):
        return load_case(case)
    if isinstance(case, Case):
        return case
    if isinstance(case, dict):
        return Case.from_dict(case)
    raise ValueError(f"case {type(case).__name__} is not allowed: pass an rvcad.Case, a case dict "
                     f"({{'errors': {{...}}, 'design': {{...}}, ...}}) or the path of a case JSON file")


def solve(case: Case | dict[str, Any] | str | Path | None = None, *, solver: str = "analytic", steps: int = 720,
          revolutions: float = 1.0, load_Nm: float | None = None, direction: int | None = None,
          law: ContactLaw | None = None, theta_in_deg: np.ndarray | None = None) -> Result:
    """Quasi-static transmission error of one case.

    Parameters
    ----------
    case : rvcad.Case, dict, str, Path or None
        The case, a case dict (``{"name", "design", "errors", "load_Nm", "direction", "model"}``, every
        key optional) or the path of a case JSON file; None: nominal, no errors.
    solver : {"analytic", "fcl"}
        Contact provider: exact envelope distances, or python-fcl on the exported meshes.
    steps : int
        Steps over the revolutions (>= 2).
    revolutions : float
        Output revolutions.
    load_Nm : float or None
        Output load torque, N m (default: the case's, 20). 0: rigid single-flank limit.
    direction : {+1, -1} or None
        Default: the case's.
    law : ContactLaw or None
        Contact law ``F = K delta**n`` (default K = 2e5 N/mm^1.5, n = 1.5).
    theta_in_deg : array or None
        Explicit input angles, deg, in the order of motion (replace ``steps`` and ``revolutions``).

    Returns
    -------
    Result
        ``.table`` (``input_deg, output_deg, te_arcsec, contacts, peak_force_N``), ``.stats``
        (``pp, mean, mean_abs, rms`` in arcsec, ratio, ...), ``.plot()``.

    Raises
    ------
    ValueError
        Naming the bad field (case keys, solver, steps, revolutions, direction, angles).
    """
    r = run_te(as_case(case), solver, steps, revolutions, load_Nm, direction, law, theta_in_deg=theta_in_deg)
    return Result(case=r.case, solver=r.solver, table=r.table, stats=r.stats)
