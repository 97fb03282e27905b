"""Single-factor screen of the Table 4 errors (paper Fig. 9) and sweeps of the RSM factors (Fig. 11).

* :func:`screen_cases` -- the error-free case A and each of the eleven Table 4 error types alone at
  its paper value (``ERROR_TYPES[key].paper_value``, default instance), optionally also at minus
  that value (used by the stack-up's one-at-a-time variance shares).
* :func:`sweep_cases` -- each RSM factor (EA = pin_pitch in deg, EB = pin_circle_diameter in um,
  EC = pin_radius in um, ED = disc_hole_eccentricity in um) alone over the Table 5 range
  (-0.06..0.06 deg, -14..14, -7..7, -14..14 um).
* :func:`run_screen` -- runs both through a *runner* (default: :func:`serial_runner`, an
  :class:`rvdyn.runner.Runner` in this process without cache; ``rv-stackup`` passes its cached,
  parallel one) and
  returns the tables, the error ranking and the check of the paper's stage I / stage II claim.
* :func:`plot_screen`, :func:`plot_sweeps` -- figures of the report (the TE figure: :mod:`rvstudy.te_figure`)
  (``rv-stackup --stages screen`` writes the tables, figures and report of this stage).

Responses, per case and over one output revolution: ``pp`` (max - min of TE), ``mean``, ``mean_abs``
(mean of |TE|, our reading of the paper's "mean value of transmission error") and ``rms``, all in
arcsec, plus ``te_mean_abs_arcmin`` and ``te_pp_arcmin``.

Ranking: the paper ranks the errors by their influence on TE (Fig. 9). Here the primary measure is
the increase of the peak-to-peak TE over case A (``d_pp_arcsec``; the load's constant elastic
wind-up cancels in it); ``rank_mean_abs`` ranks by ``|mean_abs - mean_abs(A)|`` instead.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from rvcad.atomic import atomic_path
from rvcad.errors import ERROR_TYPES, Case
from rvdyn.contacts import ContactLaw
from rvdyn.runner import Runner as ForwardRunner

from rvpaper import PAPER_DESCRIPTION, RSM_FACTORS, STAGE, TABLE5_HALF_RANGE  # noqa: E402  (re-exported)

ARCSEC_PER_ARCMIN = 60.0

#: A runner maps a list of cases to one result dict per case (same order): ``{"stats": {pp, mean,
#: mean_abs, rms, seconds, ...} (arcsec, s), "te_arcsec": array or None, "key": str, "cached": bool}``
#: (an :class:`rvdyn.runner.Runner` is one).
Runner = Callable[[Sequence[Case], str], list[dict[str, Any]]]


def _clean(v: float) -> float:
    """Round a factor value to 12 significant digits so equal settings give equal case keys."""
    v = float(f"{float(v):.12g}")
    return 0.0 if v == 0 else v


def make_case(errors: dict[str, float | list[float]], name: str, load_Nm: float = 20.0, direction: int = 1,
              base: dict[str, Any] | None = None) -> Case:
    """A case with the given default-instance error values (zeros dropped, so equal physics => equal key).

    Parameters
    ----------
    errors : dict
        ``{error_key: value}`` in the error's unit (um or deg); a pin-wise error may also take the
        list of its value at every pin.
    name : str
        Case name (not part of the cache key).
    load_Nm : float
        Output load torque, N m.
    direction : {1, -1}
    base : dict or None
        Case dict whose ``design`` and ``model`` are kept (errors are replaced).
    """
    d: dict[str, Any] = {"name": name, "load_Nm": float(load_Nm), "direction": int(direction)}
    if base:
        for k in ("design", "model"):
            if base.get(k):
                d[k] = base[k]
    clean = {k: ([_clean(x) for x in v] if isinstance(v, (list, tuple)) else _clean(v)) for k, v in errors.items()}
    d["errors"] = {k: v for k, v in clean.items() if (any(v) if isinstance(v, list) else v != 0.0)}
    return Case.from_dict(d)


def screen_cases(load_Nm: float = 20.0, both_signs: bool = False,
                 base: dict[str, Any] | None = None) -> pd.DataFrame:
    """Cases of the single-factor screen (paper Table 4 / Fig. 9).

    Parameters
    ----------
    load_Nm : float
        Output load, N m.
    both_signs : bool
        Also run every error at minus its paper value.
    base : dict or None
        Case dict supplying design and model options.

    Returns
    -------
    DataFrame
        ``letter, error, description, stage, value, unit, sign, case`` (``case`` holds the Case).
    """
    rows = [{"letter": "A", "error": "none", "description": PAPER_DESCRIPTION["A"], "stage": "-",
             "value": 0.0, "unit": "", "sign": 0, "case": make_case({}, "screen-A", load_Nm, base=base)}]
    for sign in ((1, -1) if both_signs else (1,)):
        for et in ERROR_TYPES.values():
            v = sign * et.paper_value
            tag = "+" if sign > 0 else "-"
            rows.append({"letter": et.letter, "error": et.key, "description": PAPER_DESCRIPTION[et.letter],
                         "stage": STAGE[et.letter], "value": v, "unit": et.unit, "sign": sign,
                         "case": make_case({et.key: v}, f"screen-{et.letter}{tag}", load_Nm, base=base)})
    return pd.DataFrame(rows)


def sweep_cases(points: int = 7, load_Nm: float = 20.0, half_range: dict[str, float] | None = None,
                base: dict[str, Any] | None = None) -> pd.DataFrame:
    """Cases of the factor sweeps (paper Fig. 11): each RSM factor alone over its Table 5 range.

    Parameters
    ----------
    points : int
        Points per sweep (>= 2), equally spaced from -h to +h.
    load_Nm : float
        Output load, N m.
    half_range : dict or None
        ``{factor: h}`` in the error's unit; default :data:`TABLE5_HALF_RANGE`.
    base : dict or None
        Case dict supplying design and model options.

    Returns
    -------
    DataFrame
        ``factor, error, value, unit, coded, case``.
    """
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or points < 2:
        raise ValueError(f"sweep points {points!r} must be an integer >= 2")
    hr = dict(TABLE5_HALF_RANGE if half_range is None else half_range)
    rows = []
    for f, key in RSM_FACTORS.items():
        if f not in hr:
            continue
        h = float(hr[f])
        for z in np.linspace(-1.0, 1.0, int(points)):
            v = _clean(z * h)
            rows.append({"factor": f, "error": key, "value": v, "unit": ERROR_TYPES[key].unit,
                         "coded": _clean(z),
                         "case": make_case({key: v}, f"sweep-{f}{v:+g}", load_Nm, base=base)})
    return pd.DataFrame(rows)


def serial_runner(solver: str = "analytic", steps: int = 720, law: ContactLaw | None = None,
                  progress: bool = True) -> Runner:
    """A runner that solves the cases one after another in this process, with no cache.

    Parameters
    ----------
    solver : {"analytic", "fcl"}
    steps : int
        Steps per output revolution.
    law : ContactLaw or None
        Contact law of every case; None: each case's own (``model.contact``, else rvdyn's default, physical).
    progress : bool
        Show a tqdm bar on stderr.
    """
    return ForwardRunner(None, None, solver, steps, law, progress=progress)


def _stat_columns(results: list[dict[str, Any]]) -> pd.DataFrame:
    st = pd.DataFrame([r["stats"] for r in results])
    out = pd.DataFrame({
        "pp_arcsec": st["pp"].astype(float), "mean_arcsec": st["mean"].astype(float),
        "mean_abs_arcsec": st["mean_abs"].astype(float), "rms_arcsec": st["rms"].astype(float)})
    out["te_mean_abs_arcmin"] = out["mean_abs_arcsec"] / ARCSEC_PER_ARCMIN
    out["te_pp_arcmin"] = out["pp_arcsec"] / ARCSEC_PER_ARCMIN
    out["seconds"] = st["seconds"].astype(float) if "seconds" in st else np.nan
    out["case_key"] = [r.get("key", "") for r in results]
    out["cached"] = [bool(r.get("cached", False)) for r in results]
    return out


@dataclass
class ScreenResult:
    """Outcome of :func:`run_screen`.

    Attributes
    ----------
    screen : DataFrame
        One row per screen case (A, then B..L at +paper value, then at -paper value if run):
        ``letter, error, description, stage, value, unit, sign``, the responses (arcsec/arcmin),
        ``d_pp_arcsec`` and ``d_mean_abs_arcsec`` (change from case A) and, for the +paper-value
        rows, ``rank_pp`` and ``rank_mean_abs`` (1 = largest influence).
    sweeps : DataFrame
        One row per sweep point: ``factor, error, value, unit, coded`` and the responses.
    curves : dict
        ``{case name: TE array (arcsec)}`` for the screen cases whose runner returned curves.
    stage_check : dict
        Whether the stage I errors (B, C) rank below every stage II error, per measure.
    """

    screen: pd.DataFrame
    sweeps: pd.DataFrame
    curves: dict[str, np.ndarray] = field(default_factory=dict)
    stage_check: dict[str, Any] = field(default_factory=dict)


def rank_errors(screen: pd.DataFrame) -> pd.DataFrame:
    """Add ``d_pp_arcsec``, ``d_mean_abs_arcsec`` and the ranks of the +paper-value rows.

    Parameters
    ----------
    screen : DataFrame
        Screen rows with ``letter, sign, pp_arcsec, mean_abs_arcsec`` and an ``A`` row.
    """
    s = screen.copy()
    a = s[s["letter"] == "A"]
    if a.empty:
        raise ValueError("the screen needs the error-free case A to rank the errors")
    pp0, ma0 = float(a["pp_arcsec"].iloc[0]), float(a["mean_abs_arcsec"].iloc[0])
    s["d_pp_arcsec"] = s["pp_arcsec"] - pp0
    s["d_mean_abs_arcsec"] = s["mean_abs_arcsec"] - ma0
    plus = s["sign"] == 1
    s["rank_pp"] = np.nan
    s["rank_mean_abs"] = np.nan
    # ties are broken by the other measure so the ranking is total
    order = s[plus].assign(_a=s["d_pp_arcsec"], _b=s["d_mean_abs_arcsec"].abs()).sort_values(
        ["_a", "_b"], ascending=False).index
    s.loc[order, "rank_pp"] = np.arange(1, len(order) + 1)
    order = s[plus].assign(_a=s["d_mean_abs_arcsec"].abs(), _b=s["d_pp_arcsec"]).sort_values(
        ["_a", "_b"], ascending=False).index
    s.loc[order, "rank_mean_abs"] = np.arange(1, len(order) + 1)
    return s


def stage_check(screen: pd.DataFrame) -> dict[str, Any]:
    """Do the stage I errors (B, C) rank below every stage II error (paper Fig. 9 and Sec. 5)?

    Returns
    -------
    dict
        Per measure (``pp``, ``mean_abs``): ranks of B and C, the best (smallest) stage II rank
        below them, ``reproduced`` (both stage I errors below all stage II errors) and
        ``below_rsm_factors`` (both below the four RSM factors L, I, J, G).
    """
    plus = screen[screen["sign"] == 1].set_index("letter")
    out: dict[str, Any] = {}
    for m in ("pp", "mean_abs"):
        r = plus[f"rank_{m}"]
        st1 = r[[x for x in ("B", "C") if x in r.index]]
        st2 = r[[x for x in r.index if STAGE.get(x) == "II"]]
        rsm = r[[x for x in ("L", "I", "J", "G") if x in r.index]]
        out[m] = {
            "rank_B": int(r.get("B", np.nan)) if "B" in r.index else None,
            "rank_C": int(r.get("C", np.nan)) if "C" in r.index else None,
            "worst_stage2_rank": int(st2.max()) if len(st2) else None,
            "stage2_below_stage1": sorted(st2[st2 > st1.min()].index.tolist()) if len(st1) else [],
            "reproduced": bool(len(st1) and len(st2) and st1.min() > st2.max()),
            "below_rsm_factors": bool(len(st1) and len(rsm) and st1.min() > rsm.max()),
        }
    return out


def run_screen(solver: str = "analytic", steps: int = 720, sweep_points: int = 7, load_Nm: float = 20.0,
               runner: Runner | None = None, both_signs: bool = False, law: ContactLaw | None = None,
               half_range: dict[str, float] | None = None, base: dict[str, Any] | None = None,
               progress: bool = True, sweeps: bool = True) -> ScreenResult:
    """Single-factor screen and factor sweeps.

    Parameters
    ----------
    solver : {"analytic", "fcl"}
        Contact provider (used by the default runner only).
    steps : int
        Steps per output revolution (default runner only).
    sweep_points : int
        Points per factor sweep (>= 2).
    load_Nm : float
        Output load, N m (>= 0).
    runner : callable or None
        ``runner(cases, desc) -> list of result dicts``; default :func:`serial_runner`.
    both_signs : bool
        Also run every error at minus its paper value.
    law : ContactLaw or None
        Contact law of the default runner; None: the paper's impact law (Eq. 1, ``ContactLaw()``, K = 2e5
        N/mm^1.5, n = 1.5), as rv-stackup's screen uses: this is the reproduction of the paper's Fig. 9 and
        Fig. 11 (rvdyn's own default is the physical law).
    half_range : dict or None
        Sweep half ranges ``{factor: h}``; default Table 5.
    base : dict or None
        Case dict supplying design and model options.
    progress : bool
    sweeps : bool
        Run the sweeps (False: screen only).

    Returns
    -------
    ScreenResult
    """
    if not (isinstance(load_Nm, (int, float)) and math.isfinite(load_Nm) and load_Nm >= 0):
        raise ValueError(f"load_Nm {load_Nm!r} must be a finite number >= 0 (N m)")
    if runner is None:
        runner = serial_runner(solver, steps, ContactLaw() if law is None else law, progress)
    sc = screen_cases(load_Nm, both_signs, base)
    res = runner(list(sc["case"]), "screen")
    screen = pd.concat([sc.drop(columns="case").reset_index(drop=True), _stat_columns(res)], axis=1)
    screen = rank_errors(screen)
    curves = {c.name: np.asarray(r["te_arcsec"]) for c, r in zip(sc["case"], res)
              if r.get("te_arcsec") is not None}
    if sweeps:
        sw = sweep_cases(sweep_points, load_Nm, half_range, base)
        sres = runner(list(sw["case"]), "sweeps")
        sweep = pd.concat([sw.drop(columns="case").reset_index(drop=True), _stat_columns(sres)], axis=1)
    else:
        sweep = pd.DataFrame(columns=["factor", "error", "value", "unit", "coded"])
    return ScreenResult(screen=screen, sweeps=sweep, curves=curves, stage_check=stage_check(screen))


# ---------------------------------------------------------------------------------------------- output
def save_figure_atomic(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Save a matplotlib Figure to ``path`` through a temporary file and ``os.replace``.

    The figure is drawn on an Agg canvas (pyplot and the global backend are not touched).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    path = Path(path)
    FigureCanvasAgg(fig)
    with atomic_path(path, suffix=path.suffix) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return path


def plot_screen(screen: pd.DataFrame, path: str | Path) -> Path:
    """Bar chart of the single-factor screen (paper Fig. 9 analogue): pp and mean|TE| per error."""
    from matplotlib.figure import Figure

    plus = screen[screen["sign"].isin([0, 1])].reset_index(drop=True)
    labels = [f"{r.letter}" for r in plus.itertuples()]
    colors = ["0.6" if r.stage == "-" else ("C1" if r.stage == "I" else "C0") for r in plus.itertuples()]
    fig = Figure(figsize=(10, 6.5))
    a1 = fig.add_subplot(2, 1, 1)
    a1.bar(labels, plus["pp_arcsec"], color=colors)
    a1.set_ylabel("TE peak-to-peak [arcsec]")
    a1.set_title("Single-factor screen (each Table 4 error alone at its paper value); orange = stage I")
    a1.set_yscale("symlog", linthresh=0.01)
    a2 = fig.add_subplot(2, 1, 2)
    a2.bar(labels, plus["mean_abs_arcsec"], color=colors)
    a2.axhline(float(plus.loc[plus["letter"] == "A", "mean_abs_arcsec"].iloc[0]), color="k", lw=0.8, ls="--",
               label="case A (no error)")
    a2.set_ylabel("mean |TE| [arcsec]")
    a2.set_xlabel("error type (paper Table 4 letter)")
    a2.legend(fontsize=8)
    fig.tight_layout()
    return save_figure_atomic(fig, path)


def plot_sweeps(sweeps: pd.DataFrame, path: str | Path) -> Path:
    """Response against each RSM factor swept alone (paper Fig. 11 analogue)."""
    from matplotlib.figure import Figure

    factors = list(dict.fromkeys(sweeps["factor"]))
    fig = Figure(figsize=(10, 7))
    for i, f in enumerate(factors):
        ax = fig.add_subplot(2, 2, i + 1) if len(factors) <= 4 else fig.add_subplot(1, len(factors), i + 1)
        d = sweeps[sweeps["factor"] == f].sort_values("value")
        ax.plot(d["value"], d["te_mean_abs_arcmin"], "o-", color="C0", label="mean |TE|")
        ax.set_ylabel("mean |TE| [arcmin]", color="C0")
        ax2 = ax.twinx()
        ax2.plot(d["value"], d["te_pp_arcmin"], "s--", color="C3", label="TE pp")
        ax2.set_ylabel("TE pp [arcmin]", color="C3")
        unit = str(d["unit"].iloc[0])
        ax.set_xlabel(f"{f} = {d['error'].iloc[0]} [{unit}]")
        ax.set_title(f"{f} swept alone")
    fig.tight_layout()
    return save_figure_atomic(fig, path)
