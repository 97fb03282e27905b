"""Realistic reducers (issue 10): the joint step's shortlist holds the candidates that could take the
place of the weakest effect in the model, screened with the other members refitted (Frisch-Waugh),
not only those ranked against the residual alone. Linear core, no rvdyn solves (well under a second)."""
from __future__ import annotations

import numpy as np
from linear_stubs import linear_rank

from rvcalib.effects import Effect
from rvcalib.joint import JointSelection
from rvcalib.results import Active, PoolMember
from rvcalib.selection import REPLACE_MEMBERS


def _case():
    """Truth: A at 3, C at 1.5 and D at 2, C's column 0.6 A + 0.8 w. The model holds A, a stand-in B
    (B's column A + 0.4 w + 0.2 z, fitted) and D. Candidates not in the model: C, a
    twin-like E (B's column plus a little noise: the residual-alone screening's favourite) and F
    (unrelated)."""
    rng = np.random.default_rng(3)
    nc = 300
    a, w, z, d, f = rng.normal(size=(5, nc))
    c = 0.6 * a + 0.8 * w
    b = a + 0.4 * w + 0.2 * z
    y = 3.0 * a + 1.5 * c + 2.0 * d + 0.02 * rng.normal(size=nc)
    X = np.column_stack([a, b, d])
    p, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ p
    eff = {k: Effect(f"{k}_test", f"{k}_test", "table4", "um", k) for k in "ABCDEF"}
    sel = JointSelection.__new__(JointSelection)
    sel.active = [Active(eff["A"], np.array([p[0]]), 1), Active(eff["B"], np.array([p[1]]), 1),
                  Active(eff["D"], np.array([p[2]]), 1)]
    sel.joint_new = 6
    sel.log = lambda msg: None
    members = [PoolMember(act.effect, col[:, None], col * act.p[0], lambda q, p0=act.p: p0 + np.asarray(q), act)
               for act, col in zip(sel.active, (a, b, d))]
    lib = {"C": c, "E": b + 0.05 * rng.normal(size=nc), "F": f}
    calls = []

    sel.rank = linear_rank(lib, eff, calls)
    return sel, members, r, lib, eff, calls


def test_replacement_shortlist_finds_what_takes_a_stand_ins_place():
    sel, members, r, lib, eff, calls = _case()
    # screened against the stand-in's part plus the residual with nothing refitted (as the plain
    # screening saw it before B entered), B's twin E ranks first, not C
    t = r + members[1].contribution
    plain = []
    for k, col in lib.items():
        beta = float(col @ t) / float(col @ col)
        plain.append((float((t - beta * col) @ (t - beta * col)), k))
    assert sorted(plain)[0][1] == "E"
    got = sel.replacement_shortlist(members, r, None, 1, set())
    # the weakest members are screened (B: A takes most of its part back); with A refitted, C ranks
    # first for B's place
    assert len(calls) == REPLACE_MEMBERS
    assert [d.effect.name for d in got][0] == "C_test"
    assert calls[0].shape[1] == 2  # the other members' columns (A and D) are refitted


def test_replacement_shortlist_one_per_family_and_seen():
    sel, members, r, lib, eff, calls = _case()
    seen = {"C_test"}
    got = sel.replacement_shortlist(members, r, None, 3, seen)
    names = [d.effect.name for d in got]
    assert "C_test" not in names
    assert len(names) == len(set(names))
    assert set(names) <= seen


def test_replacement_shortlist_empty_without_members():
    sel, members, r, lib, eff, calls = _case()
    assert sel.replacement_shortlist([], r, None, 3, set()) == []
    assert sel.replacement_shortlist(members, r, None, 0, set()) == []
    assert calls == []
