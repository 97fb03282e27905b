"""Linear stand-ins for the loop's screening in tests of its linear cores (no rvdyn)."""
from __future__ import annotations

import numpy as np

from rvcalib.lsq import projector
from rvcalib.results import Candidate


def linear_rank(lib: dict, eff: dict, calls: list | None = None):
    """A stand-in for ``Screening.rank``: each candidate column of ``lib`` (name -> column) fitted to ``t`` with
    ``others`` projected out, as a :class:`rvcalib.results.Candidate` of ``eff[name]``, sorted by explained
    fraction; ``calls`` collects the ``others`` of each call."""

    def rank(t, others, r_full):
        if calls is not None:
            calls.append(others)
        P = projector(others)
        tp = P(t)
        rss0 = float(tp @ tp)
        out = []
        for k, col in lib.items():
            cp = P(col)
            beta = float(cp @ tp) / float(cp @ cp)
            res = tp - beta * cp
            out.append(Candidate(eff[k], 1.0 - float(res @ res) / rss0, np.array([beta]), cp[:, None], beta * cp))
        return sorted(out, key=lambda x: -x.explained)

    return rank
