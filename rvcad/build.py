"""The reducer as build123d objects: ``rvcad.reducer(case).parts["disc0"]`` is a labelled, placed Solid.

The bd_warehouse habit: one call builds the object, derived values are attributes, the parts are
ordinary build123d shapes a user can ``show()``, combine (``+``, ``-``, ``&``) and export
(``export_step``, ``export_stl``)::

    import rvcad
    r = rvcad.reducer({})                 # nominal design; a Case, a dict or a JSON path
    r.ratio, r.design.z_pins              # 121.0, 40
    disc = r.parts["disc0"]               # build123d Solid, label "disc0", placed in the assembly
    both = r.parts["disc0"] + r.parts["disc1"]

Parts are built on first access (a cycloid disc takes about a second at the default 0.1 um
B-spline budget) and cached. They are the same OpenCASCADE solids that ``rvcad export`` writes to
STEP, placed as in ``assembly.step``. The 0.1 um STL comes from rvcad's own exact tessellation
(:meth:`rvcad.plan.Part.mesh`), not from build123d's mesher.
"""
from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from rvcad.assembly import Assembly
from rvcad.check import check_case
from rvcad.errors import Case, as_case
from rvcad.geometry import ReducerGeometry
from rvcad.params import Design
from rvcad.plan import DEFAULT_TOLERANCE_MM, AxialLayout
from rvcad.validation import OptionError, reject


class _Parts(Mapping):
    """Part name -> placed, labelled build123d Solid, built on first access and cached."""

    def __init__(self, reducer: "Reducer") -> None:
        self._r = reducer
        self._cache: dict[str, Any] = {}

    def __getitem__(self, name: str) -> Any:
        if name not in self._cache:
            if name not in self._r.assembly.parts:
                raise KeyError(f"no part {name!r}; parts: {', '.join(self._r.names[:10])}, ..., "
                               f"{self._r.names[-1]}")
            self._cache[name] = self._r.solid(name)
        return self._cache[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._r.names)

    def __len__(self) -> int:
        return len(self._r.names)

    def __repr__(self) -> str:
        return f"<rvcad parts: {len(self)} build123d solids ({len(self._cache)} built)>"


class Reducer:
    """The error-perturbed reducer of one case as build123d parts placed at one input angle.

    Parameters
    ----------
    case : Case, dict, str, Path or None
        The case (``{}`` or ``None``: the nominal design without errors).
    theta_in_deg : float
        Input (sun) angle of the placement, degrees (the other parts follow the ideal kinematics
        unless ``state`` is given).
    tolerance_mm : float
        B-spline budget of the exact curves (cycloid envelope, involute flanks), mm (default 1e-4).
    state : (theta_out_rad, (psi_0, ..., psi_(n-1)) rad: one per crank) or None
        Explicit output and crank angles (e.g. a solved pose from ``rvdyn``).
    check : bool
        Run :func:`rvcad.check.check_case` first (a case that cannot give valid solids raises
        :class:`rvcad.check.DesignError` naming the field).

    Attributes
    ----------
    case : Case
    design : Design
    geometry : ReducerGeometry
    layout : AxialLayout
    assembly : Assembly
        The plan of every part (outlines, meshes, placements).
    ratio : float
        Total ratio (121 by default).
    parts : mapping of str -> build123d.Solid
        ``sun``, ``planet0/1``, ``crank0/1``, ``flange``, ``disc0/1``, ``carrier``, ``housing``,
        ``pin00..pin39``; each labelled with its name and placed as in ``assembly.step``.
    placements : dict of str -> (x mm, y mm, rotation deg)
    check : dict
        The margins of the design check (empty when ``check=False``).
    """

    def __init__(self, case: Case | dict[str, Any] | str | Path | None = None, theta_in_deg: float = 0.0,
                 tolerance_mm: float = DEFAULT_TOLERANCE_MM, state: tuple[float, Any] | None = None,
                 check: bool = True) -> None:
        self.case = as_case(case)
        if isinstance(tolerance_mm, bool) or not (isinstance(tolerance_mm, (int, float)) and math.isfinite(tolerance_mm)
                                                  and 1e-5 <= tolerance_mm <= 0.1):
            reject("tolerance_mm", tolerance_mm, "a number in [1e-05, 0.1] mm (0.01 to 100 um)", "is out of range",
                   OptionError)
        self.tolerance_mm = float(tolerance_mm)
        self.geometry = ReducerGeometry(self.case)
        self.check = check_case(self.case, self.geometry) if check else {}
        self.assembly = Assembly(self.case, theta_in_deg, state=state, geometry=self.geometry)
        self.names = list(self.assembly.parts)
        self.parts: Mapping[str, Any] = _Parts(self)

    @property
    def design(self) -> Design:
        return self.geometry.design

    @property
    def layout(self) -> AxialLayout:
        return self.assembly.layout

    @property
    def ratio(self) -> float:
        return self.geometry.ratio

    @property
    def theta_in_deg(self) -> float:
        return self.assembly.theta_in_deg

    @property
    def placements(self) -> dict[str, tuple[float, float, float]]:
        return dict(self.assembly.placements)

    def solid(self, name: str, placed: bool = True) -> Any:
        """A new build123d Solid of one part (placed, or in its own frame), labelled with its name."""
        import build123d as bd

        s = self.assembly[name].solid(self.tolerance_mm)
        if placed:
            x, y, r = self.assembly.placements[name]
            s = s.moved(bd.Location((x, y, 0.0), (0.0, 0.0, r)))
        s.label = name
        return s

    def compound(self, names: list[str] | None = None) -> Any:
        """build123d ``Compound`` of the placed parts (all by default), children labelled."""
        import build123d as bd

        return bd.Compound(children=[self.parts[n] for n in (names or self.names)],
                           label=f"rv-reducer {self.case.name}")

    def __repr__(self) -> str:
        return (f"Reducer(case={self.case.name!r}, ratio={self.ratio:g}, parts={len(self.names)}, "
                f"theta_in_deg={self.theta_in_deg:g})")


def reducer(case: Case | dict[str, Any] | str | Path | None = None, theta_in_deg: float = 0.0,
            tolerance_mm: float = DEFAULT_TOLERANCE_MM, state: tuple[float, Any] | None = None,
            check: bool = True) -> Reducer:
    """The reducer of a case as placed, labelled build123d parts; see :class:`Reducer`."""
    return Reducer(case, theta_in_deg, tolerance_mm, state, check)


__all__ = ["Reducer", "as_case", "reducer"]
