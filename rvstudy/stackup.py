"""Monte Carlo tolerance stack-up through the full solver (``rv-stackup`` stage ``mc``).

Every draw of every toleranced feature (:mod:`rvstudy.features`) is a case solved by the quasi-static
solver (rvdyn): the analytic contact provider for all draws, the fcl provider again on a check
subsample, with their agreement reported. Responses a user puts a specification on:

* ``te_pp_arcmin`` -- TE peak-to-peak over one output revolution at the study's load (the industry's
  angular transmission error), arcmin;
* ``play_3pct_arcmin`` -- a two-direction proxy of lost motion: at each of :func:`play_positions`
  locked input positions evenly spread over one output revolution, the output angle under an output
  torque of +3 % of rated minus that under -3 % (the solver's TE of direction -1 minus that of
  direction +1 at a load of 3 % rated: an external torque +tau is direction -1 with load tau), the
  largest over the positions, arcmin. It is read on the elastic (friction-free) curve of
  ``rvdyn.stiffness`` (equal to its points, tested); the maker's lost motion of ``rvdyn.stiffness`` is
  read on the hysteresis curve with its friction band (0.02 % apart for a 5 um pin clearance at
  input 0, tested to 0.1 %), and is taken at one input angle, hence the other name. ``rvdyn.stiffness.hysteresis`` itself is not used per draw: its
  zero-torque point is the rigid limit, which refuses a preloaded draw (nearly every draw of the pin
  tolerances) as an interference;
* ``torsional_rigidity_Nm_per_arcmin`` -- b/a of the same elastic curve as ``rvdyn.stiffness`` reads it
  (secant between 3 % and 100 % of rated torque, b = 0.97 T_rated, mean of both sides) but on the
  elastic curve, without the friction band (2.7 % stiffer figure from rvdyn.stiffness for the 5 um
  clearance case), smallest over the positions, N m/arcmin;
* ``te_mean_abs_arcmin`` -- the paper's mean |TE| (for the paper reproduction; no specification by
  default).

Draws: ``mc_draws`` independent draws (seed ``[seed, 2]``) give every distribution statistic. The
contributors come from a designed sample (Saltelli): A and B are the first two blocks of
``mc_sobol`` independent draws, and for every tolerance one more block of ``mc_sobol`` cases, A with
that tolerance's features taken from B (:func:`rvstudy.capability.sobol_from_design`). Tolerance
allocation re-weights the independent draws (:func:`rvstudy.capability.allocation`; no new solves).
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd

from rvcad.errors import ERROR_TYPES, Case
from rvcad.params import Design
from rvstudy.capability import allocation, capability, recommend, sobol_from_design
from rvstudy.features import Feature, draw, features, group_columns, make_draw_case

ARCSEC_PER_ARCMIN = 60.0
#: Fraction of the rated torque at which lost motion is read (conventions: +-3 %).
PLAY_LOAD_FRACTION = 0.03
#: Responses of the full-solver Monte Carlo and their labels.
MC_RESPONSES = {
    "te_pp_arcmin": "TE peak-to-peak [arcmin]",
    "play_3pct_arcmin": "two-direction play at +-3 % rated torque [arcmin] (lost-motion proxy)",
    "torsional_rigidity_Nm_per_arcmin": "torsional rigidity b/a [N m/arcmin]",
    "te_mean_abs_arcmin": "mean |TE| [arcmin] (paper's response)",
}

Runner = Callable[..., list[dict[str, Any]]]
#: The play/rigidity solves of a draw: name, fraction of the rated torque, direction (positive torque on the
#: output = direction -1).
PLAY_RUNS = (("dp_3", PLAY_LOAD_FRACTION, 1), ("dm_3", PLAY_LOAD_FRACTION, -1), ("dp_full", 1.0, 1),
             ("dm_full", 1.0, -1))


def play_positions(design: Design) -> int:
    """Number of input positions of the play proxy: the first of 37, 41, 43, 47, 53 that divides none of
    Zp, Zc and the rounded ratio, so that the positions fall at distinct crank phases."""
    for p in (37, 41, 43, 47, 53):
        if all(int(v) % p for v in (design.z_pins, design.z_disc, round(design.ratio))):
            return p
    return 59


def factor_values(feats: list[Feature], X: pd.DataFrame, fs: Any) -> pd.DataFrame | None:
    """Each RSM factor's value in the draws as the surface knows it: the default-instance feature (pin 0's
    pitch, disc 0 hole 0, ...), or the mean over the pins for an all-pins error or an ``all`` pattern;
    None when a factor has no such reading (an ``alternate`` pattern)."""
    out = {}
    for f in fs.names:
        key, pat = fs.errors[f], fs.patterns.get(f)
        et = ERROR_TYPES[key]
        cols = [ft for ft in feats if ft.tolerance == key and ft.component == "value"]
        if pat == "alternate":
            return None
        if not cols:
            out[f] = np.zeros(len(X))
            continue
        all_pins = pat == "all" or (et.pinwise and et.defaults.get("pin", 0) is None)
        if all_pins:
            out[f] = X[[c.name for c in cols]].to_numpy(float).mean(axis=1)
            continue
        d = tuple(sorted((k, v) for k, v in et.defaults.items() if v is not None))
        hit = [c for c in cols if d in c.instances]
        out[f] = X[hit[0].name].to_numpy(float) if hit else np.zeros(len(X))
    return pd.DataFrame(out)


def draw_cases(feats: list[Feature], X: pd.DataFrame, design: Design, prefix: str, load: float,
               base_model: dict, notes: list[str], start: int = 0) -> list[Case | None]:
    """The validated case of each draw at the study load, direction +1 (None for a draw that is not a valid
    case: a note says why and the draw counts as failed)."""
    dd = design.to_dict()
    vals = X.to_numpy(float)
    out: list[Case | None] = []
    for i in range(len(X)):
        try:
            out.append(make_draw_case(feats, vals[i], design, f"{prefix}-{start + i + 1}", load, 1, base_model, dd))
        except ValueError as exc:
            notes.append(f"Monte Carlo draw {prefix}-{start + i + 1} is not a valid case (counted as a failed draw): "
                         f"{exc}")
            out.append(None)
    return out


def play_loads(design: Design, rated_Nm: float, notes: list[str]) -> list[tuple[str, float, int]]:
    """``(name, load N m, direction)`` of the four play/rigidity solves (:data:`PLAY_RUNS` at ``rated_Nm``);
    empty, with a note, when such a load is not a valid case load."""
    out = []
    for name, frac, d in PLAY_RUNS:
        try:
            Case.from_dict({"design": design.to_dict(), "load_Nm": frac * rated_Nm, "direction": d})
        except ValueError as exc:
            notes.append(f"the play/rigidity solves are left out (every draw's play and rigidity count as failed): "
                         f"{exc}")
            return []
        out.append((name, frac * rated_Nm, d))
    return out


def _stat(r: dict[str, Any] | None, k: str) -> float:
    if r is None or r.get("status", "ok") != "ok":
        return float("nan")
    return float(r["stats"][k]) / ARCSEC_PER_ARCMIN


def torsion_arcmin(r: dict | None) -> np.ndarray | None:
    """Output torsion angle (arcmin) at the positions in input-angle order (a direction -1 run is reversed),
    or None for a failed solve."""
    if r is None or r.get("status") != "ok" or r.get("te_arcsec") is None:
        return None
    te = np.asarray(r["te_arcsec"], float) / ARCSEC_PER_ARCMIN
    return te[::-1] if r.get("direction", 1) == -1 else te


def play_at_positions(plus3: dict | None, minus3: dict | None) -> np.ndarray | None:
    """theta(+3 %) - theta(-3 %) at each position, arcmin: TE of direction -1 minus TE of direction +1."""
    a, b = torsion_arcmin(minus3), torsion_arcmin(plus3)
    return None if a is None or b is None else a - b


def rigidity_at_positions(r: dict[str, dict | None], rated_Nm: float) -> np.ndarray | None:
    """b/a at each position, N m/arcmin: b = 0.97 T_rated, a = the torsion between 3 % and 100 % of rated
    torque on each side, mean of both sides (``rvdyn.stiffness`` reads the curve so). The equilibrium alone:
    ``rvdyn.stiffness`` adds the housing ring in series (rvdyn.housing; 0.045 arcsec of 117 at rated torque on
    the default design), which these readings leave out."""
    t = {k: torsion_arcmin(v) for k, v in r.items()}
    if any(v is None for v in t.values()):
        return None
    b = (1.0 - PLAY_LOAD_FRACTION) * rated_Nm
    # positive torque = direction -1; angles of +100 % minus +3 %, and of -3 % minus -100 %
    return 0.5 * (b / (t["dm_full"] - t["dm_3"]) + b / (t["dp_3"] - t["dp_full"]))


def responses_of(cases: list[Case | None], design: Design, cfg: Any, runner: Runner, notes: list[str],
                 desc: str) -> pd.DataFrame:
    """Solve the draws (TE at the study load; play and rigidity at +-3 % and +-100 % rated) and return the
    responses, one row per draw.

    Parameters
    ----------
    cases : list of Case or None
        Each draw's case at the study load (:func:`draw_cases`); None = not a valid case (a failed draw).
    runner : Runner
        An analytic runner; the five solves of a draw go to one worker task (``group``): one case read and
        geometry built per draw, the four play solves batched.
    """
    loads = play_loads(design, cfg.rated_Nm, notes)
    n_pos = play_positions(design)
    batch, steps, group, slot = [], [], [], []
    for i, c in enumerate(cases):
        if c is None:
            continue
        batch.append(c)
        steps.append(int(cfg.steps))
        slot.append((i, "te"))
        for name, load, d in loads:  # same errors: only the load and the direction change (no new validation)
            batch.append(dataclasses.replace(c, load_Nm=float(load), direction=int(d)))
            steps.append(n_pos)
            slot.append((i, name))
        group.extend([i] * (1 + len(loads)))
    res: dict[tuple[int, str], dict[str, Any]] = {}
    if batch:
        for sl, r, d in zip(slot, runner(batch, desc, steps=steps, group=group), [c.direction for c in batch]):
            res[sl] = {**r, "direction": d}
    te = [res.get((i, "te")) for i in range(len(cases))]
    play, rig = [], []
    for i in range(len(cases)):
        curve = {name: res.get((i, name)) for name, _, _ in PLAY_RUNS}
        pl = play_at_positions(curve["dp_3"], curve["dm_3"])
        rg = rigidity_at_positions(curve, cfg.rated_Nm)
        play.append(float(np.max(pl)) if pl is not None else float("nan"))
        rig.append(float(np.min(rg)) if rg is not None else float("nan"))
    return pd.DataFrame({
        "te_pp_arcmin": [_stat(r, "pp") for r in te],
        "play_3pct_arcmin": play,
        "torsional_rigidity_Nm_per_arcmin": rig,
        "te_mean_abs_arcmin": [_stat(r, "mean_abs") for r in te],
        "status": ["ok" if r is not None and r.get("status") == "ok" else "failed" for r in te],
        "error_message": ["invalid case" if r is None else r.get("error", "") for r in te],
    })


def designed_sample(X: pd.DataFrame, groups: dict[str, list[str]], n_s: int) -> pd.DataFrame:
    """The designed draws of the contributors: for every tolerance group a block of A (the first ``n_s``
    rows of ``X``) with that group's columns taken from B (the next ``n_s`` rows); empty if ``n_s < 2``."""
    if n_s < 2 or not groups:
        return pd.DataFrame(columns=X.columns)
    A, B = X.iloc[:n_s].reset_index(drop=True), X.iloc[n_s:2 * n_s].reset_index(drop=True)
    AB = []
    for cols in groups.values():
        m = A.copy()
        m[cols] = B[cols].to_numpy()
        AB.append(m)
    return pd.concat(AB, ignore_index=True)


def solve_full_mc(cfg: Any, design: Design, runners: dict[str, Runner], base_model: dict | None = None,
                  background: Any = None) -> dict[str, Any]:
    """Draw and solve every Monte Carlo case (the part of :func:`run_full_mc` that needs the workers).

    Parameters
    ----------
    cfg, design, runners, base_model
        As :func:`run_full_mc`.
    background : concurrent.futures.Executor or None
        A thread pool: the fcl check is then submitted at once, before the draws, and solved beside them.

    Returns
    -------
    dict
        ``feats, X, Xab, groups, n_s, cases, Y, Yab, check`` (fcl results of the check draws or None),
        ``notes``, ``t0`` (start, ``time.perf_counter``), ``counts`` (the runners' counters before).
    """
    t0 = time.perf_counter()
    done0 = {k: (getattr(r, "computed", 0), getattr(r, "reused", 0), getattr(r, "worker_seconds", 0.0))
             for k, r in runners.items()}
    notes: list[str] = []
    tols = cfg.tolerances
    base_model = dict(base_model or {})
    feats = features(tols, design)
    X = draw(tols, feats, cfg.mc_draws, np.random.default_rng([cfg.seed, 2]))
    groups = {g: c for g, c in group_columns(feats).items() if tols[g].std > 0}
    n_s = min(int(cfg.mc_sobol), len(X) // 2)
    Xab = designed_sample(X, groups, n_s)
    n_chk = min(int(cfg.mc_check), len(X)) if "check" in runners else 0
    cases = draw_cases(feats, X.iloc[:n_chk], design, "mc", cfg.load_Nm, base_model, notes)
    idx = [i for i in range(n_chk) if cases[i] is not None]

    def check() -> list[dict[str, Any] | None]:
        got = dict(zip(idx, runners["check"]([cases[i] for i in idx], f"MC check: fcl ({n_chk} draws)")
                       if idx else []))
        return [got.get(i) for i in range(n_chk)]

    chk = background.submit(check) if background is not None and n_chk else None
    cases = (cases + draw_cases(feats, X.iloc[n_chk:], design, "mc", cfg.load_Nm, base_model, notes, start=n_chk)
             + draw_cases(feats, Xab, design, "sobol", cfg.load_Nm, base_model, notes))
    # the independent and the designed draws in one batch (no wait between them)
    Yall = responses_of(cases, design, cfg, runners["mc"], notes,
                        f"MC: {len(X)} + {len(Xab)} designed draws x {1 + len(PLAY_RUNS)} solves")
    checked = (chk.result() if chk is not None else check()) if n_chk else None
    return {"feats": feats, "X": X, "Xab": Xab, "groups": groups, "n_s": n_s, "cases": cases,
            "Y": Yall.iloc[:len(X)].reset_index(drop=True), "Yab": Yall.iloc[len(X):].reset_index(drop=True),
            "check": checked, "notes": notes, "t0": t0, "counts": done0}


def run_full_mc(cfg: Any, fs: Any, design: Design, runners: dict[str, Runner], fits: dict[str, Any],
                notes: list[str], base_model: dict | None = None, workers: int = 1,
                solved: dict[str, Any] | None = None) -> dict[str, Any]:
    """The full-solver Monte Carlo of the study (see the module docstring).

    Parameters
    ----------
    cfg : StudyConfig
        Uses ``tolerances, mc_draws, mc_sobol, mc_check, seed, load_Nm, rated_Nm, specs()``.
    fs : FactorSet
        The RSM factors (for the surface comparison).
    design : Design
        The reducer.
    runners : dict
        ``mc`` (analytic; the TE at ``cfg.steps``, the play at :func:`play_positions` steps, per case) and
        optionally ``check`` (fcl, ``cfg.steps``): :class:`rvdyn.runner.Runner` objects.
    fits : dict
        Response -> FitBundle of the design stage (surface comparison), may be empty.
    notes : list
        Notes of the run (appended to).
    workers : int
        Workers of the executor (for the throughput figure).
    solved : dict or None
        The output of :func:`solve_full_mc` when the solves ran already (beside other stages); default:
        solved here.
    """
    sv = solved if solved is not None else solve_full_mc(cfg, design, runners, base_model)
    notes.extend(sv["notes"])
    tols = cfg.tolerances
    feats, X, groups, Y = sv["feats"], sv["X"], sv["groups"], sv["Y"]
    n_design = len(sv["Xab"])
    specs = cfg.specs()
    out: dict[str, Any] = {"tolerances": tols, "n_features": len(feats), "specs": specs,
                           "play_positions": play_positions(design), "play_load_Nm": PLAY_LOAD_FRACTION * cfg.rated_Nm,
                           "features": pd.DataFrame([{"feature": f.name, "tolerance": f.tolerance,
                                                      "component": f.component} for f in feats])}
    out["sobol_n"] = sv["n_s"]
    out["sobol"] = _sobol_table(Y, sv["Yab"], groups, sv["n_s"], cfg.seed) if n_design else pd.DataFrame()
    out["responses"], out["allocation"] = _capabilities(Y, X, groups, tols, specs, out["sobol"], cfg.yield_target)
    out["surface"] = _surface_comparison(feats, X, Y, fs, fits, specs)
    if sv["check"] is not None:
        out["check"], out["check_agreement"] = _fcl_check(Y, sv["check"])
    out["draws"] = pd.concat([X, Y], axis=1)
    out["timing"] = _mc_timing(sv["t0"], sv["counts"], runners, len(X), n_design, workers)
    return out


def _sobol_table(Y: pd.DataFrame, Yab: pd.DataFrame, groups: dict[str, Any], n_s: int, seed: int) -> pd.DataFrame:
    """Variance-based indices of every tolerance group for every response, from the designed sample.

    ``Y``'s first two blocks of ``n_s`` rows are the matrices A and B; ``Yab`` holds one block of ``n_s``
    rows per group of ``groups`` (A with that group's features from B), in its order. Returns one row per
    response and group (:func:`rvstudy.capability.sobol_from_design` with a ``response`` column first).
    """
    sob_rows = []
    for resp in MC_RESPONSES:
        yA, yB = Y[resp].to_numpy()[:n_s], Y[resp].to_numpy()[n_s:2 * n_s]
        yab = {g: Yab[resp].to_numpy()[j * n_s:(j + 1) * n_s] for j, g in enumerate(groups)}
        s = sobol_from_design(yA, yB, yab, var=float(np.nanvar(Y[resp].to_numpy())), seed=seed)
        s.insert(0, "response", resp)
        sob_rows.append(s)
    return pd.concat(sob_rows, ignore_index=True) if sob_rows else pd.DataFrame()


def _capabilities(Y: pd.DataFrame, X: pd.DataFrame, groups: dict[str, Any], tols: dict[str, Any],
                  specs: dict[str, Any], sob: pd.DataFrame,
                  yield_target: float) -> tuple[dict[str, Any], pd.DataFrame]:
    """Capability of each response on the independent draws, its contributors and its tolerance allocation.

    Returns
    -------
    per : dict
        Response -> :func:`rvstudy.capability.capability` dict with ``contributors`` (from ``sob``) and,
        for a response with a limit whose allocation table is not empty, the ``allocation`` recommendation.
    alloc : DataFrame
        The allocation tables of every response with a limit, ``response`` column first.
    """
    per: dict[str, Any] = {}
    alloc_rows = []
    for resp in MC_RESPONSES:
        lsl, usl = specs.get(resp, (None, None))
        c = capability(Y[resp].to_numpy(), lsl, usl)
        c["contributors"] = ([{"tolerance": r.tolerance, "first_order": r.first_order, "total": r.total}
                              for r in sob[sob["response"] == resp].itertuples()] if len(sob) else [])
        if lsl is not None or usl is not None:
            a = allocation(X, groups, tols, Y[resp].to_numpy(), lsl, usl)
            if len(a):
                a.insert(0, "response", resp)
                alloc_rows.append(a)
                c["allocation"] = recommend(a, target=yield_target)
        per[resp] = c
    return per, (pd.concat(alloc_rows, ignore_index=True) if alloc_rows else pd.DataFrame())


def _surface_comparison(feats: list[Feature], X: pd.DataFrame, Y: pd.DataFrame, fs: Any, fits: dict[str, Any],
                        specs: dict[str, Any]) -> dict[str, Any]:
    """The design stage's quadratic surface on the same draws, against the full solver (comparison only).

    For each TE response with a fit, adds the column ``<response>_surface`` (the prediction) to ``Y`` and
    returns response -> ``n, rmse, bias, max_abs`` of surface - solver (arcmin), the fraction of negative
    predictions, their correlation and the yield the surface would give; empty when a factor has no
    reading in the draws (:func:`factor_values`) or no fit exists.
    """
    Z = factor_values(feats, X, fs)
    surf = {}
    for resp, key in (("te_pp_arcmin", "pp_arcmin"), ("te_mean_abs_arcmin", "mean_abs_arcmin")):
        b = fits.get(key)
        if Z is None or b is None or getattr(b, "results", None) is None:
            continue
        pred = np.asarray(b.results.surface.predict(Z, units="actual"), float)
        Y[f"{resp}_surface"] = pred
        ok = np.isfinite(Y[resp].to_numpy())
        e = pred[ok] - Y[resp].to_numpy()[ok]
        lsl, usl = specs.get(resp, (None, None))
        surf[resp] = {"n": int(ok.sum()), "rmse": float(np.sqrt(np.mean(e ** 2))), "bias": float(np.mean(e)),
                      "max_abs": float(np.max(np.abs(e))), "negative_fraction": float(np.mean(pred < 0)),
                      "corr": float(np.corrcoef(pred[ok], Y[resp].to_numpy()[ok])[0, 1]) if ok.sum() > 2 else None,
                      "yield_surface": (capability(pred, lsl, usl)["yield"] if lsl is not None or usl is not None
                                        else None)}
    return surf


def _fcl_check(Y: pd.DataFrame, chk: list[dict[str, Any] | None]) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The fcl solves of the first independent draws beside their analytic results, and their agreement.

    Returns the table (``draw`` and each TE response by both providers, arcmin) and, per response,
    ``n, max_abs_diff, rms_diff`` over the draws both providers solved (None when there is none).
    """
    n_chk = len(chk)
    cdf = pd.DataFrame({"draw": np.arange(1, n_chk + 1),
                        "te_pp_arcmin_analytic": Y["te_pp_arcmin"].to_numpy()[:n_chk],
                        "te_pp_arcmin_fcl": [_stat(r, "pp") for r in chk],
                        "te_mean_abs_arcmin_analytic": Y["te_mean_abs_arcmin"].to_numpy()[:n_chk],
                        "te_mean_abs_arcmin_fcl": [_stat(r, "mean_abs") for r in chk]})
    agr = {}
    for r in ("te_pp_arcmin", "te_mean_abs_arcmin"):
        d = (cdf[f"{r}_fcl"] - cdf[f"{r}_analytic"]).to_numpy()
        d = d[np.isfinite(d)]
        agr[r] = {"n": int(d.size), "max_abs_diff": float(np.max(np.abs(d))) if d.size else None,
                  "rms_diff": float(np.sqrt(np.mean(d ** 2))) if d.size else None}
    return cdf, agr


def _mc_timing(t0: float, done0: dict[str, Any], runners: dict[str, Runner], n_indep: int, n_design: int,
               workers: int) -> dict[str, Any]:
    """Throughput of the Monte Carlo since ``t0``: wall and worker seconds, solves computed and reused.

    ``done0`` holds each runner's ``(computed, reused, worker_seconds)`` when the draws started; the fcl
    ``check`` runner is left out.
    """
    wall = time.perf_counter() - t0
    n_eval = n_indep + n_design
    computed = sum(getattr(r, "computed", 0) - done0[k][0] for k, r in runners.items() if k != "check")
    reused = sum(getattr(r, "reused", 0) - done0[k][1] for k, r in runners.items() if k != "check")
    busy = sum(getattr(r, "worker_seconds", 0.0) - done0[k][2] for k, r in runners.items() if k != "check")
    return {"wall_s": wall, "full_solver_draws": n_eval, "independent_draws": n_indep,
            "analytic_solves_computed": computed, "analytic_solves_reused": reused,
            "design_draws": n_design, "solves_per_draw": 1 + len(PLAY_RUNS), "workers": workers,
            "worker_s": busy, "draws_per_s_wall": n_eval / wall if wall > 0 else float("nan"),
            # worker time on the Monte Carlo tasks (case reading, geometry, the five solves): the rate
            # of one worker, also when the draws shared the workers with other stages
            "draws_per_s_per_worker": (n_eval / busy if busy > 0 else
                                       n_eval / wall / max(1, workers) if wall > 0 else float("nan"))}
