"""Screening: every library candidate's signature (the change of the model TE when it is set to its
typical size) solved on the screening grid at the declared model, and fitted to the current residual
(linear, piecewise in the sign or quadrant); the harmonic-only competitors; the pair look-ahead.

Pin instances and the direction of the pin-circle offset and ovality reuse the solved signature
rotated by whole pin pitches / grid steps (rotational symmetry of the pins), crank/disc/hole
instances their half-turn twin's (see :func:`rvcalib.effects.build_library`).
"""
from __future__ import annotations

import hashlib
import math
import time
from typing import Callable

import numpy as np

from rvcalib.dataset import RunRecord
from rvcalib.effects import Effect, polar_to_xy, trial_points
from rvcalib.forward import ModelEvaluationError, grid_te_many
from rvcalib.lsq import fit_option, ftest, projector
from rvcalib.model import LoopModel
from rvcalib.results import Candidate, EmpiricalTerm, HarmonicCandidate


def coarse_values(run: RunRecord, values: np.ndarray, m: int, period: float) -> np.ndarray:
    """A run's sampled values at the m screening grid angles (``period``: input angle of one output
    revolution, deg).

    Where every grid angle holds samples (records on the grid), the mean of its samples (all
    revolutions). Otherwise a band-limited resampling: a Fourier series of the output angle up to
    the order both the record and the grid resolve (below half the samples per revolution and
    half the grid) fitted by least squares to all samples and evaluated at the grid angles. Linear
    interpolation would attenuate the orders near the record's Nyquist order (order 80 of a record
    of 240 samples per revolution by a third), where the TE of cam and pin errors has content.
    """
    x = np.mod(run.input_deg, period)
    step = period / m
    k = x / step
    kr = np.rint(k)
    on = np.abs(k - kr) < 1e-6
    idx = kr.astype(int) % m
    if on.all():
        s = np.bincount(idx, weights=values, minlength=m)
        c = np.bincount(idx, minlength=m)
        if np.all(c > 0):
            return s / c
    return _resampler(run, m, period) @ np.asarray(values, dtype=float)


_RESAMPLERS: dict[tuple, np.ndarray] = {}


def _resampler(run: RunRecord, m: int, period: float) -> np.ndarray:
    """The (m, n) matrix of :func:`coarse_values`'s band-limited resampling of a run (cached)."""
    x = np.mod(run.input_deg, period)
    key = (hashlib.blake2b(x.tobytes(), digest_size=16).hexdigest(), int(m), float(period))
    R = _RESAMPLERS.get(key)
    if R is None:
        spr = run.n / max(run.revolutions, 1e-12)
        K = int(max(1, min(m // 2 - 1, math.floor(spr / 2.0 - 1e-9) - 1)))
        th = 2.0 * np.pi * x / period
        orders = np.arange(1, K + 1)
        A = np.column_stack([np.ones_like(th), np.cos(np.outer(th, orders)), np.sin(np.outer(th, orders))])
        tg = 2.0 * np.pi * np.arange(m) / m
        G = np.column_stack([np.ones_like(tg), np.cos(np.outer(tg, orders)), np.sin(np.outer(tg, orders))])
        R = G @ np.linalg.pinv(A, rcond=1e-10)
        if len(_RESAMPLERS) > 64:
            _RESAMPLERS.clear()
        _RESAMPLERS[key] = R
    return R


class Screening(LoopModel):
    """The screening stage of the loop (methods on the loop's model)."""

    def _ms(self, e: Effect) -> int:
        """Screening grid points of an effect (a multiple of the pin count that divides the coarse grid)."""
        ms = e.screen_steps or self.m
        return ms if (ms < self.m and self.m % ms == 0 and ms % self.design.z_pins == 0) else self.m

    def coarse_residual(self, pairs: list[tuple[Effect, np.ndarray]] | None = None) -> list[np.ndarray]:
        """The residual of every run at the current state, or at the effects and parameters ``pairs``
        (data minus the model solved at the readings), taken to the screening grid
        (:func:`coarse_values`), arcsec, one array per run."""
        return [coarse_values(r, y - q, self.m, self.period)
                for r, y, q in zip(self.runs, self.y, self.predict(self._pairs() if pairs is None else pairs))]

    def screening_signatures(self) -> None:
        """Solve every template candidate at its trial values on its screening grid, per condition,
        at the declared model (one batch of the forward runner: :func:`rvcalib.forward.grid_te_many`)."""
        t0 = time.perf_counter()
        self.solve_signatures([e for e in self.lib.templates() if not e.expensive], [])  # expensive: on demand
        self.log(f"screening signatures: {len(self.sig)} candidates x {len(self.cond_base)} conditions on "
                 f"{self.m} points in {time.perf_counter() - t0:.1f} s")

    def solve_signatures(self, templates: list[Effect], state: list[tuple[Effect, np.ndarray]]) -> int:
        """Solve the screening signatures of ``templates`` at a model state (``state``: effects and
        parameters in the model; empty = the declared model): for each trial value the change of
        the model TE on the effect's screening grid, per condition. Stored in ``self.sig`` (the
        ranking uses them from then on) with the state's size in ``self.sig_state``. Returns the
        number of rvdyn trial solves asked for (cache hits included)."""
        phys = [(e, p) for e, p in state if e.family != "measurement"]
        self._solve_signatures(templates, phys)
        for e in templates:
            self.sig_state[e.name] = len(phys)
        return sum(len(trial_points(e)) for e in templates) * len(self.cond_base)

    def _solve_signatures(self, effects: list[Effect], phys: list[tuple[Effect, np.ndarray]] | None = None) -> None:
        """``self.sig[e.name]``: per trial value of each effect, per condition, the change of the model
        TE on the effect's screening grid (None for a trial value rvdyn cannot evaluate), at the declared
        model plus the physical effects ``phys``. The base cases and every trial case are solved in one
        batch."""
        phys = list(phys or [])
        nc = len(self.cond_base)
        cases: list[dict] = []
        steps: list[int] = []
        base_at: dict[int, int] = {}  # screening grid -> index of its first base case in the batch
        plan: list[tuple[Effect, int, list[int]]] = []  # effect, grid, first batch index of each trial value
        for e in effects:
            ms = self._ms(e)
            if ms not in base_at:
                base_at[ms] = len(cases)
                cases += list(self.cond_base) if not phys else [self._case(c, phys) for c in range(nc)]
                steps += [ms] * nc
            firsts = []
            for p in trial_points(e):
                firsts.append(len(cases))
                cases += [self._case(c, phys + [(e, p)]) for c in range(nc)]
                steps += [ms] * nc
            plan.append((e, ms, firsts))
        te = grid_te_many(cases, steps)
        for ms, i0 in base_at.items():
            for c in range(nc):
                if isinstance(te[i0 + c], ModelEvaluationError):
                    raise te[i0 + c]  # the model state itself cannot be evaluated
        for e, ms, firsts in plan:
            sigs: list[list[np.ndarray] | None] = []
            for i in firsts:
                got = te[i:i + nc]
                sigs.append(None if any(isinstance(g, ModelEvaluationError) for g in got)
                            else [g - te[base_at[ms] + c] for c, g in enumerate(got)])
            self.sig[e.name] = sigs

    def meas_coarse(self, e: Effect, ms: int | None = None) -> np.ndarray:
        """A measurement effect's columns at every run's screening points, taken there from its values
        at the readings exactly as the residual is (:func:`coarse_values`), so that effects that depend
        on the absolute reading (a scale error) match the residual of every run and direction."""
        ms = self.m if ms is None else int(ms)
        cache = self.__dict__.setdefault("_meas_cache", {})
        if e.name not in cache:
            blocks = []
            for r in self.runs:
                B = e.basis(r.input_deg, r.output_deg)
                blocks.append(np.column_stack([coarse_values(r, B[:, k], self.m, self.period)
                                               for k in range(B.shape[1])]))
            cache[e.name] = blocks
        sub = self.m // ms
        return np.vstack([b[::sub] for b in cache[e.name]])

    def _ensure_expensive(self, rc: np.ndarray, P) -> None:
        """Solve the screening signatures of the expensive candidates (cam-bearing clearance) when the
        residual has a significant offset or direction-dependent offset (p < 0.01): a clearance
        always shows as lost motion far larger than its ripple, so without one it cannot be there."""
        todo = [e for e in self.lib.templates() if e.expensive and e.name not in self.sig]
        if not todo:
            return
        cols = [np.ones(self.nc)]
        if len({r.direction for r in self.runs}) > 1:
            cols.append(np.concatenate([np.full(self.m, float(r.direction)) for r in self.runs]))
        A = np.column_stack([P(c) for c in cols])
        rss0 = float(rc @ rc)
        c, *_ = np.linalg.lstsq(A, rc, rcond=None)
        rss1 = float(np.sum((rc - A @ c) ** 2))
        _, pv = ftest(rss0, rss1, A.shape[1], self.nc, self._p_cur() + A.shape[1])
        if pv >= 0.01:
            return
        t0 = time.perf_counter()
        self._solve_signatures(todo)
        self.log(f"screening signatures of {', '.join(e.name for e in todo)} (the residual has an offset) in "
                 f"{time.perf_counter() - t0:.1f} s")

    def _sig_stack(self, e: Effect, j: int, roll_deg: float = 0.0) -> np.ndarray | None:
        """Trial j's signature of effect e over all runs' screening points, rotated by ``roll_deg``
        of output angle (a whole number of grid steps)."""
        src = self.sig.get(e.template or e.name)
        if e.trial_map is not None:
            j = e.trial_map[j]
        if src is None or src[j] is None:
            return None
        s = src[j]
        ms = s[0].size
        roll = int(round(roll_deg / 360.0 * ms))
        return np.concatenate([np.roll(s[self.cond_of[i]], roll) if roll else s[self.cond_of[i]]
                               for i in range(len(self.runs))])

    def _options(self, e: Effect, meas_cols: np.ndarray | None) -> list[tuple[np.ndarray, bool, Callable]]:
        """Screening options of an effect: (columns, nonneg, coefficients -> parameters)."""
        s = e.scale
        opts: list[tuple[np.ndarray, bool, Callable]] = []
        if e.screen in ("two_sided", "one_sided"):
            for j, sign in enumerate([1.0, -1.0] if e.screen == "two_sided" else [1.0]):
                S = self._sig_stack(e, j, e.shift_deg)
                if S is not None:
                    opts.append((S[:, None], True, lambda c, sign=sign: np.array([sign * c[0] * s])))
        elif e.screen == "vector4":
            S = [self._sig_stack(e, j) for j in range(4)]
            u = [np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([-1.0, 0.0]), np.array([0.0, -1.0])]
            for q in range(4):
                a, b = S[q], S[(q + 1) % 4]
                if a is None or b is None:
                    continue
                opts.append((np.column_stack([a, b]), True,
                             lambda c, q=q: s * (c[0] * u[q] + c[1] * u[(q + 1) % 4])))
        elif e.screen == "angle_shift":
            ms = self._ms(e)
            for j in range(int(round(ms * e.angle_period_deg / 360.0))):
                ang = 360.0 * j / ms
                S = self._sig_stack(e, 0, ang)
                if S is None:
                    continue
                opts.append((S[:, None], True, lambda c, ang=ang: polar_to_xy(c[0] * s, ang, e.polar_factor)))
        elif e.screen == "analytic" and meas_cols is not None:
            opts.append((meas_cols, False, lambda c: np.array(c, dtype=float)))
        return opts

    def _group(self, ms: int, rc_cat: np.ndarray, Ec: np.ndarray | None):
        """Residual, projector and residual sum of squares restricted to an ``ms``-point grid."""
        idx = self._sub_idx(ms)
        Pg = projector(None if Ec is None else Ec[idx])
        r = Pg(rc_cat[idx])
        return r, Pg, float(r @ r)

    def rank(self, rc_cat: np.ndarray, Ec: np.ndarray | None, r_full: np.ndarray | None = None) -> list[Candidate]:
        """Screen every candidate against the coarse residual (``rc_cat``: unprojected, concatenated).

        Measurement effects (analytic) are fitted to the full residual ``r_full`` (projected) when
        given: on the coarse grid the input encoder's order 121 aliases onto low orders.

        Returns the candidates sorted by explained fraction (descending).
        """
        groups: dict[int, tuple] = {}
        active_names = {a.effect.name for a in self.active}
        out = []
        for e in self.lib:
            if e.name in active_names:
                continue
            d = self.screen_effect(e, groups, rc_cat, Ec, r_full)
            if d is not None:
                out.append(d)
        # ties (e.g. pins 20 apart, whose TE signatures coincide) go to the library order
        order = {e.name: i for i, e in enumerate(self.lib)}
        out.sort(key=lambda d: (-round(d.explained, 6), order[d.effect.name]))
        return out

    def screen_effect(self, e: Effect, groups: dict, rc_cat: np.ndarray, Ec: np.ndarray | None,
                      r_full: np.ndarray | None = None) -> Candidate | None:
        """One candidate's screening fit to the coarse residual (see :meth:`rank`; ``groups`` caches
        the residual per screening grid)."""
        ms = self._ms(e)
        if ms not in groups:
            groups[ms] = self._group(ms, rc_cat, Ec)
        r, Pg, rss0 = groups[ms]
        if rss0 <= 0:
            return None
        meas = None
        if e.screen == "analytic":
            meas = self.meas_coarse(e, ms)
            if r_full is not None:
                expl, c = self._analytic_full(e, r_full)
                cols = np.column_stack([Pg(meas[:, k]) for k in range(meas.shape[1])]) if ms == self.m else None
                return Candidate(e, expl, c, cols, None if cols is None else cols @ c,
                                 to_p=lambda b: np.asarray(b, dtype=float))
        best = None
        for A, nonneg, to_p in self._options(e, meas):
            A = np.column_stack([Pg(A[:, k]) for k in range(A.shape[1])])
            rss, c = fit_option(r, A, nonneg)
            if best is None or rss < best[0]:
                best = (rss, to_p(c), A, A @ c, to_p)
        if best is None:
            return None
        return Candidate(e, 1.0 - best[0] / rss0, best[1], best[2] if ms == self.m else None,
                         best[3] if ms == self.m else None, to_p=best[4])

    def lookahead(self, ranking: list[Candidate], rc: np.ndarray, n_top: int = 12) -> list[Candidate]:
        """Re-order the ranking by what each candidate explains together with its best partner.

        Greedy forward selection can pick one effect whose signature mimics the sum of two others
        (a cam-bearing clearance for a cam error plus a torsional compliance). For the ``n_top``
        best candidates (one per family) the best pair of their screening signatures is fitted
        jointly (linear least squares on the coarse grid). If the best pair leaves less than half
        the residual the best single candidate leaves, candidates are ordered by the explained
        fraction of the best pair they belong to (rounded to 1e-3), then by their own; otherwise
        the order stays. Each candidate gets ``pair_explained`` and ``partner``.
        """
        fam_seen: set[str] = set()
        top: list[dict] = []
        for d in ranking:
            fam = d.family_key
            if fam in fam_seen or d.cols is None:
                continue
            fam_seen.add(fam)
            top.append(d)
            if len(top) >= n_top:
                break
        rss0 = float(rc @ rc)
        if rss0 <= 0 or len(top) < 2:
            return ranking
        for d in ranking:
            d.pair_explained = d.explained
            d.partner = None
        for i in range(len(top)):
            for j in range(i + 1, len(top)):
                A = np.column_stack([top[i].cols, top[j].cols])
                c, *_ = np.linalg.lstsq(A, rc, rcond=None)
                res = rc - A @ c
                expl = 1.0 - float(res @ res) / rss0
                for a, b in ((top[i], top[j]), (top[j], top[i])):
                    if expl > a.pair_explained:
                        a.pair_explained = expl
                        a.partner = b.effect.name
        order = {id(d): k for k, d in enumerate(ranking)}
        best_single = max(d.explained for d in ranking)
        best_pair = max(d.pair_explained for d in ranking)
        if 1.0 - best_pair > 0.5 * (1.0 - best_single):
            return ranking  # no pair explains much more than the best single candidate: keep the order
        return sorted(ranking, key=lambda d: (-round(d.pair_explained, 3), -round(d.explained, 6),
                                              order[id(d)]))

    def _analytic_full(self, e: Effect, r_full: np.ndarray) -> tuple[float, np.ndarray]:
        """Explained fraction and components of a measurement effect fitted to the full residual."""
        P = projector(self._emp_matrix(self.empirical))
        A = np.vstack([e.basis(r.input_deg, r.output_deg) for r in self.runs])
        A = np.column_stack([P(A[:, k]) for k in range(A.shape[1])])
        c, *_ = np.linalg.lstsq(A, r_full, rcond=None)
        res = r_full - A @ c
        rss0 = float(r_full @ r_full)
        return (1.0 - float(res @ res) / rss0 if rss0 > 0 else 0.0), c

    def harmonic_candidates(self) -> list[EmpiricalTerm]:
        """The empirical terms screened beside the library: a constant, a direction-signed constant,
        a load-proportional constant, and every order below the screening grid's Nyquist order, the
        same in every run, proportional to the load or with the sign of the direction (the last two
        only where the runs differ in load / direction)."""
        loads = len({r.load_Nm for r in self.runs}) > 1
        dirs = len({r.direction for r in self.runs}) > 1
        factors = ["common"] + (["load"] if loads else []) + (["direction"] if dirs else [])
        cands = [EmpiricalTerm("offset")] + ([EmpiricalTerm("direction_offset")] if dirs else [])
        cands += [EmpiricalTerm("offset", 0, "load")] if loads else []
        cands += [EmpiricalTerm("harmonic", k, f) for k in range(1, self.m // 2) for f in factors]
        return cands

    def harmonic_rank(self, rc: np.ndarray, P) -> list[HarmonicCandidate]:
        """Best empirical terms (:meth:`harmonic_candidates`) fitted alone to the residual."""
        rss0 = float(rc @ rc)
        have = set(self.empirical)
        cands = self.harmonic_candidates()
        out = []
        th = np.radians(self.coarse_out_deg)
        for t in cands:
            if t in have:
                continue
            A = np.vstack([t.columns(th, r.direction, r.load_Nm) for r in self.runs])
            A = np.column_stack([P(A[:, k]) for k in range(A.shape[1])])
            if np.linalg.norm(A) < 1e-12:
                continue
            rss, _ = fit_option(rc, A, False)
            out.append(HarmonicCandidate(t, rss, 1.0 - rss / rss0, A))
        out.sort(key=lambda d: d.rss)
        return out
