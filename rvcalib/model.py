"""The loop's model of a dataset: run conditions (runs that share a declared case are solved once),
the effects and empirical terms in the model, and the model TE at every reading
(:func:`rvcalib.forward.te_at`) or on a screening grid (:func:`rvcalib.forward.grid_te`)."""
from __future__ import annotations

import json
import time
from typing import Callable

import numpy as np

from rvcalib.dataset import MeasuredDataset
from rvcalib.effects import Effect, Library, build_library
from rvcalib.forward import ModelEvaluationError, grid_te_many, merge_case, te_at_many
from rvcalib.orders import screen_grid
from rvcalib.residual import samples_per_rev
from rvcalib.results import Active, EmpiricalTerm


def _raise_any(results: list) -> list[np.ndarray]:
    """The arrays of a batch of the forward model; its first :class:`ModelEvaluationError` raised."""
    for r in results:
        if isinstance(r, ModelEvaluationError):
            raise r
    return results


class LoopModel:
    """The loop's model of one dataset: run conditions, the current effects and empirical terms, and
    the model TE at the readings and on the screening grids (see :mod:`rvcalib.identify`).

    Parameters
    ----------
    dataset : MeasuredDataset
    steps : int or None
        Requested screening grid, points per output revolution (see
        :func:`rvcalib.orders.screen_grid`: used when it resolves the orders that matter of the
        dataset's reducer and is not larger than needed; otherwise the smallest grid that does,
        with a note). None: that smallest grid.
    alpha : float
        Family-wise significance level of the F tests (Bonferroni over the hypotheses screened).
    max_terms : int
        Largest number of effects plus empirical terms added.
    top_k : int
        Candidates validated through the nonlinear model per iteration.
    library : Library or None
        Candidates (default :func:`rvcalib.effects.build_library`).
    log : callable or None
        Called with progress strings.
    screen_points : int or None
        An explicit screening grid (refused unless it resolves the orders that matter).
    time_budget_s : float or None
        Stop adding terms once this many seconds have passed (the result says so).
    joint : bool
        Select jointly among a shortlist at the current state (:mod:`rvcalib.joint`); False: the
        greedy forward selection alone.
    joint_new : int
        New candidates in the joint shortlist (one per family).
    rescreen_every : int
        Re-solve the whole library's screening signatures at the current state after every this
        many accepted changes (0: never; the shortlist's families are re-solved at every joint step).
    """

    def __init__(self, dataset: MeasuredDataset, steps: int | None = None, alpha: float = 0.01,
                 max_terms: int = 6, top_k: int = 4, library: Library | None = None,
                 log: Callable[[str], None] | None = None, screen_points: int | None = None,
                 time_budget_s: float | None = None, joint: bool = True, joint_new: int = 6,
                 rescreen_every: int = 0) -> None:
        if not 0 < alpha < 1:
            raise ValueError(f"alpha {alpha!r} must lie in (0, 1)")
        if isinstance(max_terms, bool) or not isinstance(max_terms, (int, np.integer)) or max_terms < 1:
            raise ValueError(f"max_terms {max_terms!r} must be an integer >= 1")
        if time_budget_s is not None and not (np.isfinite(time_budget_s) and time_budget_s > 0):
            raise ValueError(f"time_budget_s {time_budget_s!r} must be a positive number of seconds")
        for name, v in (("joint_new", joint_new), ("rescreen_every", rescreen_every)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"{name} {v!r} must be an integer >= 0")
        self.time_budget_s = None if time_budget_s is None else float(time_budget_s)
        self.joint = bool(joint)
        self.joint_new = int(joint_new)
        self.rescreen_every = int(rescreen_every)
        self.ds = dataset
        self.design = dataset.design
        self.ratio = float(dataset.ratio)
        self.period = float(dataset.period_deg)
        steps = int(steps) if isinstance(steps, np.integer) else steps
        screen_points = int(screen_points) if isinstance(screen_points, np.integer) else screen_points
        self.m, grid_note = screen_grid(self.design, steps, screen_points)
        self.steps = self.m
        self.alpha = float(alpha)
        self.max_terms = int(max_terms)
        self.top_k = int(top_k)
        self.lib = library if library is not None else build_library(dataset)
        self.log = log or (lambda s: None)
        self.runs = dataset.runs
        self.base = [r.case_dict() for r in self.runs]
        for b in self.base:
            b.pop("name", None)
        # conditions: runs that share a declared case are solved once
        keys: dict[str, int] = {}
        self.cond_of: list[int] = []
        self.cond_base: list[dict] = []
        for b in self.base:
            k = json.dumps(b, sort_keys=True)
            if k not in keys:
                keys[k] = len(self.cond_base)
                self.cond_base.append(b)
            self.cond_of.append(keys[k])
        self._cond_runs = [[i for i, c in enumerate(self.cond_of) if c == cc] for cc in range(len(self.cond_base))]
        self.y = [r.te_arcsec for r in self.runs]
        self.n = int(sum(v.size for v in self.y))
        self.nc = self.m * len(self.runs)
        gdeg = np.arange(self.m) * (self.period / self.m)
        self.coarse_in_deg = gdeg
        self.coarse_out_deg = gdeg / self.ratio
        self.active: list[Active] = []
        self.empirical: list[EmpiricalTerm] = []
        self.emp_coef = np.zeros(0)
        self.sig: dict[str, list[list[np.ndarray] | None]] = {}
        #: template -> number of physical effects in the state its signatures were solved at
        self.sig_state: dict[str, int] = {}
        #: accepted physical changes since the library's signatures were last solved
        self.rescreen_due = 0
        self.notes: list[str] = list(self.lib.notes) + ([grid_note] if grid_note else [])
        self._emp_info: dict[EmpiricalTerm, tuple[int, float]] = {}
        self.fit_stats: list[dict] = []
        #: ``time.perf_counter()`` at the start of the loop (set by the loop; the time budget counts from it)
        self.t_start: float | None = None

    def _deadline(self) -> float | None:
        """``time.perf_counter()`` value at which the time budget runs out (None: no budget or not started)."""
        if self.time_budget_s is None or self.t_start is None:
            return None
        return self.t_start + self.time_budget_s

    def over_budget(self) -> bool:
        """Whether the time budget has run out."""
        d = self._deadline()
        return d is not None and time.perf_counter() > d

    def budget_stop(self, where: str) -> str:
        """The ``stopped_by`` text of a time budget that ran out at ``where`` (a stage of the loop)."""
        return (f"the time budget ({self.time_budget_s:g} s) stopped the search {where} after "
                f"{time.perf_counter() - (self.t_start or 0.0):.0f} s: the residual may hold more")

    # ------------------------------------------------------------------ model
    def _case(self, i_cond: int, active: list[tuple[Effect, np.ndarray]]) -> dict:
        errs: list[tuple[str, dict]] = []
        model: dict[str, float] = {}
        for e, p in active:
            errs.extend(e.error_items(p))
            model.update(e.model_options(p))
        return merge_case(self.cond_base[i_cond], errs, model)

    def _phys_grid(self, active: list[tuple[Effect, np.ndarray]], steps: int,
                   sensitivity: bool = False) -> list[np.ndarray]:
        """Model TE on the grid for each condition (``sensitivity``: :func:`rvcalib.forward.te_at_many`'s)."""
        phys = [(e, p) for e, p in active if e.family != "measurement"]
        return _raise_any(grid_te_many([self._case(c, phys) for c in range(len(self.cond_base))], steps,
                                       sensitivity=sensitivity))

    def _meas(self, active, input_deg: np.ndarray, output_deg: np.ndarray) -> np.ndarray:
        out = np.zeros(np.asarray(input_deg).size)
        for e, p in active:
            if e.family == "measurement":
                out = out + e.reading_arcsec(input_deg, output_deg, p)
        return out

    def predict(self, active: list[tuple[Effect, np.ndarray]]) -> list[np.ndarray]:
        """Model TE (physics + measurement effects) at every sample of every run, arcsec.

        The physics is solved exactly at the readings (:func:`rvcalib.forward.te_at`, one solve per
        run condition over the union of its runs' readings), not interpolated from the model grid:
        the TE has kinks and crank-order content that no practical grid resolves.
        """
        out = self.predict_many([active])[0]
        if isinstance(out, ModelEvaluationError):
            raise out
        return out

    def predict_many(self, actives: list[list[tuple[Effect, np.ndarray]]], sensitivity: bool = False
                     ) -> list[list[np.ndarray] | ModelEvaluationError]:
        """:meth:`predict` of several model states in one batch of the forward runner (with several
        workers the states' solves spread over them); a state rvdyn cannot evaluate gives its
        :class:`ModelEvaluationError` in its place. ``sensitivity``: sensitivity solves from the newest
        converged state of each run condition (:func:`rvcalib.forward.te_at_many`), for differences taken
        from that state (a Jacobian's columns)."""
        return self._solve_states(actives, None, sensitivity)

    def predict_rows(self, actives: list[list[tuple[Effect, np.ndarray]]], keep: np.ndarray,
                     sensitivity: bool = False) -> list[np.ndarray | ModelEvaluationError]:
        """Model TE of several states at some of the samples only: ``keep`` (bool, one per sample of the
        concatenated runs) selects them; each state's TE comes back concatenated over the kept samples (arcsec).
        The physics is solved at the kept readings alone, exactly as :meth:`predict_many` solves all of them;
        ``sensitivity`` as there (from the newest converged solve at the same readings)."""
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != (self.n,):
            raise ValueError(f"keep has shape {keep.shape}; one flag per sample ({self.n}) is needed")
        out = []
        for got in self._solve_states(actives, self.split(keep), sensitivity):
            out.append(got if isinstance(got, ModelEvaluationError) else np.concatenate(got))
        return out

    def subset_rows(self, per_rev: float) -> np.ndarray:
        """Every k-th reading of each run (bool per sample of the concatenated runs), k the largest that leaves at
        least ``per_rev`` readings per output revolution (every reading of a sparser run)."""
        keep = []
        for run in self.runs:
            k = max(1, int(samples_per_rev(run) // per_rev))
            m = np.zeros(run.n, dtype=bool)
            m[::k] = True
            keep.append(m)
        return np.concatenate(keep)

    def _solve_states(self, actives, keep: list[np.ndarray] | None, sensitivity: bool
                      ) -> list[list[np.ndarray] | ModelEvaluationError]:
        """The states' TE per run, at each run's samples (``keep``: a mask per run, else all)."""
        nc = len(self._cond_runs)
        sel = [slice(None) if keep is None else keep[i] for i in range(len(self.runs))]
        xs = [np.concatenate([self.runs[i].input_deg[sel[i]] for i in members]) for members in self._cond_runs]
        cases = []
        for active in actives:
            phys = [(e, p) for e, p in active if e.family != "measurement"]
            cases += [self._case(c, phys) for c in range(nc)]
        tes = te_at_many(cases, xs * len(actives), sensitivity=sensitivity)
        result: list[list[np.ndarray] | ModelEvaluationError] = []
        for k, active in enumerate(actives):
            mine = tes[k * nc:(k + 1) * nc]
            bad = next((t for t in mine if isinstance(t, ModelEvaluationError)), None)
            if bad is not None:
                result.append(bad)
                continue
            out: list[np.ndarray] = [np.empty(0)] * len(self.runs)
            for members, te in zip(self._cond_runs, mine):
                j = 0
                for i in members:
                    r = self.runs[i]
                    a, b = r.input_deg[sel[i]], r.output_deg[sel[i]]
                    out[i] = te[j:j + a.size] + self._meas(active, a, b)
                    j += a.size
            result.append(out)
        return result

    def predict_grid(self, active, ms: int | None = None, sensitivity: bool = False) -> list[np.ndarray]:
        """Model TE at the points of an ``ms``-point grid (default the coarse grid) for every run,
        solved on that grid (``ms`` divides the coarse grid). ``sensitivity``: as in :meth:`predict_many`
        (for a difference from the state solved last on that grid)."""
        ms = self.m if ms is None else int(ms)
        g = self._phys_grid(active, ms, sensitivity)
        sub = self.m // ms
        meas = self._meas(active, self.coarse_in_deg[::sub], self.coarse_out_deg[::sub])
        return [g[self.cond_of[i]] + meas for i in range(len(self.runs))]

    def _sub_idx(self, ms: int) -> np.ndarray:
        """Indices of an ``ms``-point grid's points in the concatenated coarse vector."""
        sub = self.m // ms
        return np.concatenate([i * self.m + np.arange(0, self.m, sub) for i in range(len(self.runs))])

    def _emp_matrix(self, terms: list[EmpiricalTerm], coarse: bool = False) -> np.ndarray | None:
        if not terms:
            return None
        blocks = []
        for r in self.runs:
            th = np.radians(self.coarse_out_deg) if coarse else np.radians(r.input_deg / self.ratio)
            blocks.append(np.column_stack([t.columns(th, r.direction, r.load_Nm) for t in terms]))
        return np.vstack(blocks)

    def _pairs(self, active: list[Active] | None = None) -> list[tuple[Effect, np.ndarray]]:
        return [(a.effect, a.p) for a in (self.active if active is None else active)]

    def full_residual(self, active_pairs, terms: list[EmpiricalTerm], rows: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Concatenated residual after projecting out the empirical terms, and their coefficients (``rows``: at
        those samples only, bool per sample, solved there by :meth:`predict_rows`)."""
        if rows is None:
            pred = self.predict(active_pairs)
            r = np.concatenate([y - p for y, p in zip(self.y, pred)])
        else:
            got = self.predict_rows([active_pairs], rows)[0]
            if isinstance(got, ModelEvaluationError):
                raise got
            r = np.concatenate(self.y)[rows] - got
        E = self._emp_matrix(terms)
        if E is not None and rows is not None:
            E = E[rows]
        if E is None:
            return r, np.zeros(0)
        coef, *_ = np.linalg.lstsq(E, r, rcond=None)
        return r - E @ coef, coef

    def refresh_state(self) -> np.ndarray:
        """The residual of the present model (its effects and empirical terms) on all samples, with
        ``emp_coef`` and ``rss_full`` set from it (the one place the loop's state figures are refreshed
        after the model changed)."""
        r, self.emp_coef = self.full_residual(self._pairs(), self.empirical)
        self.rss_full = float(r @ r)
        return r

    def split(self, v: np.ndarray) -> list[np.ndarray]:
        """Split a concatenated per-sample vector into runs."""
        out, i = [], 0
        for y in self.y:
            out.append(v[i:i + y.size])
            i += y.size
        return out

    def _state_key(self) -> tuple:
        """The present model state (its effects and empirical terms) as a key: the checks before the stop run
        once per state, and what they leave for the final state is kept under it."""
        return tuple(sorted(a.effect.name for a in self.active)), tuple(t.label for t in self.empirical)

    def _p_cur(self) -> int:
        """Parameters in the model now (effects' components and empirical columns)."""
        return sum(a.effect.n_params for a in self.active) + sum(t.n_cols for t in self.empirical)
