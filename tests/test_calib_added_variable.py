"""Before the loop stops it tests each candidate with the model's members refitted (the added-variable,
Frisch-Waugh-Lovell test), not only with them held at their sizes (issue 10, realistic draws: an
all-pins pin circle diameter that resembles the members was never named). Linear core, no rvdyn
solves (well under a second)."""
from __future__ import annotations

import numpy as np
from linear_stubs import linear_rank

from rvcalib.effects import Effect
from rvcalib.lsq import ftest
from rvcalib.replace import ReplacementRefit
from rvcalib.results import Active, Candidate, PoolMember

NC = 300
THR = 0.01 / 570  # the loop's Bonferroni level on the realistic draws (570 hypotheses)


def _case(c_size: float):
    """Truth: A at 3, D at 2 and C at ``c_size``, C's column 0.98 A + 0.2 w (C resembles the member A).
    The model holds A and D, fitted (A absorbs most of C). Candidates: C and an unrelated F."""
    rng = np.random.default_rng(5)
    a, w, d, f = rng.normal(size=(4, NC))
    c = 0.98 * a + 0.2 * w
    y = 3.0 * a + 2.0 * d + c_size * c + 0.1 * rng.normal(size=NC)
    X = np.column_stack([a, d])
    p, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ p
    eff = {k: Effect(f"{k}_test", f"{k}_test", "table4", "um", k) for k in "ACDF"}
    sel = ReplacementRefit.__new__(ReplacementRefit)
    sel.active = [Active(eff["A"], np.array([p[0]]), 1), Active(eff["D"], np.array([p[1]]), 1)]
    sel.empirical = []
    sel.thr = THR
    sel.nc = NC
    members = [PoolMember(act.effect, col[:, None], col * act.p[0], lambda q, p0=act.p: p0 + np.asarray(q), act)
               for act, col in zip(sel.active, (a, d))]
    sel.active_members = lambda Pc=None: members
    lib = {"C": c, "F": f}

    sel.rank = linear_rank(lib, eff)
    return sel, r, lib


def test_the_plain_screening_misses_a_candidate_that_resembles_a_member():
    sel, r, lib = _case(1.0)
    # members held at their sizes: C's fit to the residual removes (r.c)^2 / |c|^2, not significant
    c = lib["C"]
    rss0 = float(r @ r)
    expl = (float(c @ r) ** 2 / float(c @ c)) / rss0
    _, pv = ftest(rss0, rss0 * (1.0 - expl), 1, NC, 3)
    assert pv > THR


def test_added_variable_ranking_finds_it_with_the_members_refitted():
    sel, r, lib = _case(1.0)
    ranking, rec = sel.added_variable_ranking(r, None)
    assert ranking and ranking[0].effect.name == "C_test"
    assert rec["best"] == "C_test" and rec["p"] < THR and rec["delta_bic"] < 0
    # A's part of C is given back: C's coefficient is its size, not the small leftover
    assert abs(float(ranking[0].p[0]) - 1.0) < 0.05


def test_added_variable_ranking_empty_at_the_truth():
    sel, r, lib = _case(0.0)
    ranking, rec = sel.added_variable_ranking(r, None)
    assert ranking == []
    assert rec["p"] >= THR


# ---------------------------------------------------------------------- siblings of crank/disc/hole instances

def _sibling_case(model_names: list[str], own_name: str):
    """A ReplacementRefit on the paper's library (no dataset, no rvdyn): the model holds ``model_names``;
    the screening is stubbed (every candidate explains a fixed fraction, its start its library index)."""
    from rvcad.params import Design
    from rvcalib.effects import build_library
    lib = build_library(design=Design())
    sel = ReplacementRefit.__new__(ReplacementRefit)
    sel.lib = lib
    sel.active = [Active(lib.by_name(n), np.array([-1.5 if n == own_name else 1.0]), 1) for n in model_names]
    sel.runs, sel.m, sel.n, sel.nc = [None], 4, 4, 4
    sel._pairs = lambda active=None: [(a.effect, a.p) for a in sel.active]
    sel._grid_cat = lambda pairs: np.full(4, float(len(pairs)))
    order = {e.name: i for i, e in enumerate(lib)}

    def screen_effect(x, groups, target, Ec, r_full=None):
        return Candidate(x, 0.5, np.array([float(order[x.name])]), None, None)

    sel.screen_effect = screen_effect
    return sel, lib


def test_a_disc_hole_instance_has_the_other_family_as_sibling_not_its_twin():
    own = "disc_hole_eccentricity[disc=1,hole=0]"
    sel, lib = _sibling_case([own, "carrier_hole_eccentricity[crank=0]"], own)
    a = sel.active[0]
    sibs = [x.name for x, _ in sel.siblings(a, np.zeros(4), n=4, sigma2=1.0, other_families=True)]
    # its half-turn twin (disc 0 hole 1, the same TE) is not offered; of the other family (disc 0 hole 0
    # and its twin disc 1 hole 1) one instance is, the family's first
    assert sibs == ["disc_hole_eccentricity[disc=0,hole=0]"]
    # at entry (the sibling refit after a step) its family is its twin only, which the data cannot prefer
    assert sel.siblings(a, np.zeros(4), n=4, sigma2=1.0) == []


def test_no_sibling_of_a_family_already_in_the_model():
    own = "cam_eccentricity[crank=1,disc=0]"
    sel, lib = _sibling_case([own, "cam_eccentricity[crank=0,disc=0]"], own)
    assert sel.siblings(sel.active[0], np.zeros(4), n=4, sigma2=1.0, other_families=True) == []
    # a twin-only family (carrier hole of crank 0 / crank 1) has none either
    sel, lib = _sibling_case(["carrier_hole_eccentricity[crank=1]"], "carrier_hole_eccentricity[crank=1]")
    assert sel.siblings(sel.active[0], np.zeros(4), n=4, sigma2=1.0, other_families=True) == []


# ---------------------------------------------------------------------- look-alike refit before the stop

def _lookalike_case(c_size: float):
    """Truth: A at 3, D at 2 and C at ``c_size`` with C's column 0.95 A + 0.31 w (C looks like the member A).
    The model holds A and D; the full model is linear here (the refit is least squares), so the stub checks
    the mechanism: which candidate is refitted beside which member, and the acceptance (F test and BIC on
    all samples)."""
    rng = np.random.default_rng(11)
    a, w, d, f = rng.normal(size=(4, NC))
    c = 0.95 * a + 0.31 * w
    y = 3.0 * a + 2.0 * d + c_size * c + 0.1 * rng.normal(size=NC)
    return _lookalike_selection({"A": a, "D": d, "C": c, "F": f}, y, ("C", "F"))


def _lookalike_selection(cols: dict, y: np.ndarray, cands: tuple):
    """A :class:`ReplacementRefit` on a linear model: members A and D (least squares at ``y``), the library
    ``cands`` (each its own error type), the refits least squares; returns it and the list of refits made."""
    eff = {k: Effect(f"{k}_test", f"{k}_test", "table4", "um", k) for k in cols}
    col_of = {eff[k].name: v for k, v in cols.items()}
    sel = ReplacementRefit.__new__(ReplacementRefit)
    X = np.column_stack([cols["A"], cols["D"]])
    p, *_ = np.linalg.lstsq(X, y, rcond=None)
    sel.active = [Active(eff["A"], np.array([p[0]]), 1), Active(eff["D"], np.array([p[1]]), 1)]
    sel.empirical = []
    sel.thr, sel.n = THR, NC
    sel.log = lambda msg: None
    sel.over_budget = lambda: False
    sel._p_cur = lambda: len(sel.active)
    sel._pairs = lambda active=None: [(x.effect, x.p) for x in sel.active]

    def residual(pairs):
        return y - sum((col_of[e.name] * float(q[0]) for e, q in pairs), np.zeros(NC))

    sel.full_residual = lambda pairs, terms: (residual(pairs), np.zeros(0))
    r0 = residual(sel._pairs())
    sel.rss_full = float(r0 @ r0)
    sel.active_members = lambda Pc=None: [
        PoolMember(x.effect, col_of[x.effect.name][:, None], col_of[x.effect.name] * float(x.p[0]),
                   lambda q, p0=x.p: p0 + np.asarray(q), x) for x in sel.active]
    fits = []

    def fit_full(effects, p0, terms):
        fits.append([e.name for e in effects])
        A = np.column_stack([col_of[e.name] for e in effects])
        q, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ q
        return [np.array([v]) for v in q], float(r @ r), q, None, A

    sel.fit_full = fit_full
    sel.keep_state_jacobian = lambda: None  # the stub's refits are least squares: no start Jacobian to keep
    sel.rank = linear_rank({k: cols[k] for k in cands}, eff)
    return sel, fits


def test_lookalike_refit_adds_the_members_look_alike_when_the_data_need_it():
    sel, fits = _lookalike_case(1.0)
    got = sel.lookalike_refit(7)
    assert got == ("A_test", "C_test")
    # each member's look-alike refitted once, beside every member
    assert ["A_test", "D_test", "C_test"] in fits
    c = next(x for x in sel.active if x.effect.name == "C_test")
    assert abs(float(c.p[0]) - 1.0) < 0.05
    assert c.info["selection"]["method"] == "look-alike refit before the stop"


def test_lookalike_refit_adds_nothing_at_the_truth():
    sel, fits = _lookalike_case(0.0)
    assert sel.lookalike_refit(7) is None
    assert [x.effect.name for x in sel.active] == ["A_test", "D_test"]


def _lookalike_pair_case(s_size: float):
    """Truth: A at 3, D at 2 and ``s_size (B - E)``, where B = 0.95 A + 0.3 w + 0.1 z and E = 0.95 A + 0.3 w -
    0.1 z are two error types that look alike (correlation 0.98) and like the member A: the truth is along
    their difference (0.2 z), which B alone reaches only in part (10 % of it, with w it must carry)."""
    rng = np.random.default_rng(5)
    a, w, z, d, f = rng.normal(size=(5, NC))
    b = 0.95 * a + 0.3 * w + 0.1 * z
    e = 0.95 * a + 0.3 * w - 0.1 * z
    y = 3.0 * a + 2.0 * d + s_size * (b - e) + 0.1 * rng.normal(size=NC)
    return _lookalike_selection({"A": a, "D": d, "B": b, "E": e, "F": f}, y, ("B", "E", "F"))


def test_lookalike_refit_adds_a_pair_that_only_together_passes():
    sel, fits = _lookalike_pair_case(0.4)
    got = sel.lookalike_refit(7)
    # neither alone passes the loop's F test at its Bonferroni level (else a single name would come back)
    assert got == ("A_test", "B_test and E_test") or got == ("A_test", "E_test and B_test")
    singles = [f for f in fits if len(f) == 3]
    assert singles, "the single look-alike is tried first"
    assert ["A_test", "D_test", "B_test", "E_test"] in fits or ["A_test", "D_test", "E_test", "B_test"] in fits
    sizes = {x.effect.name: float(x.p[0]) for x in sel.active}
    assert abs(sizes["B_test"] - 0.4) < 0.1 and abs(sizes["E_test"] + 0.4) < 0.1
    assert abs(sizes["A_test"] - 3.0) < 0.1
    assert sel.active[-1].info["selection"]["together_with"]


def test_lookalike_pair_not_added_without_its_difference():
    sel, fits = _lookalike_pair_case(0.0)
    assert sel.lookalike_refit(7) is None
    assert [x.effect.name for x in sel.active] == ["A_test", "D_test"]
