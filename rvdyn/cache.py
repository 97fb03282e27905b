"""Content-keyed cache of solved cases, written atomically and verified on read.

A *job* is one quasi-static TE solve: a case (:class:`rvcad.errors.Case`), the contact provider
(``solver``), the number of ``steps`` per output revolution, the ``revolutions`` and the contact
``law`` (K, n, rigid), or instead of steps and revolutions explicit input angles (``theta_in_deg``,
e.g. the readings of a test rig). Its key is the sha256 of ``Case.key()`` (design, errors, load,
direction, model options), those settings and a fingerprint of the physics source files
(:func:`code_fingerprint`), so a changed solver never serves stale numbers.

Each entry is one JSON file ``<dir>/<key[:2]>/<key>.json`` holding the statistics, the TE curve
(arcsec) and a sha256 checksum of its payload. Entries are written to a temporary file in the same
folder, flushed, fsynced and renamed with :func:`os.replace`, so a killed run leaves either the
whole entry or none. An entry that does not parse, lacks a field, has another key or fails its
checksum is ignored (and overwritten when the case is recomputed).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from rvcad.atomic import atomic_path
from rvcad.errors import Case
from rvdyn.contacts import ContactLaw

#: Bump when the entry layout changes.
CACHE_VERSION = 1

#: Packages whose source decides the numbers of a solve: every module of them enters the key
#: (a new physics module is covered without being listed), except those below.
PHYSICS_PACKAGES = ("rvcad", "rvdyn")
#: Modules of those packages that do not decide the numbers (the runner, this cache, the API and CLIs).
NOT_PHYSICS = frozenset({"rvcad.__main__", "rvcad.cli", "rvdyn.__main__", "rvdyn.cli", "rvdyn.api",
                         "rvdyn.cache", "rvdyn.runner"})
#: Modules used by the fcl provider only (in the fingerprint of fcl jobs only).
FCL_MODULES = frozenset({"rvdyn.collision", "rvdyn.fcl_contacts"})


def physics_modules(solver: str = "analytic") -> list[str]:
    """Names of the modules whose source enters the key of a ``solver`` job, sorted."""
    import importlib.util

    out = []
    for pkg in PHYSICS_PACKAGES:
        spec = importlib.util.find_spec(pkg)
        for folder in (spec.submodule_search_locations or []) if spec else []:
            for f in Path(folder).glob("*.py"):
                name = pkg if f.stem == "__init__" else f"{pkg}.{f.stem}"
                if name in NOT_PHYSICS or (name in FCL_MODULES and solver != "fcl"):
                    continue
                out.append(name)
    return sorted(set(out))


@lru_cache(maxsize=4)
def code_fingerprint(solver: str = "analytic") -> str:
    """sha256 (16 hex) of the source of :func:`physics_modules` (names and bytes)."""
    import importlib.util

    h = hashlib.sha256()
    for m in physics_modules(solver):
        h.update(m.encode())
        spec = importlib.util.find_spec(m)
        if spec is not None and spec.origin and os.path.exists(spec.origin):
            h.update(Path(spec.origin).read_bytes())
    return h.hexdigest()[:16]


@dataclass(frozen=True)
class Job:
    """One TE solve.

    Attributes
    ----------
    case : Case
    solver : str
        ``analytic`` or ``fcl``.
    steps : int
        Steps per ``revolutions`` output turns.
    revolutions : float
        Output revolutions (default 1).
    law : ContactLaw
        Contact law (K in N/mm^n, exponent n, rigid flag).
    theta_in_deg : tuple of float or None
        Explicit input angles, deg, in the order of motion (they replace ``steps`` and
        ``revolutions``; see :func:`rvdyn.te.run_te`). Their float64 bytes enter the key.
    max_outer : int or None
        None: a converged solve. 1: a sensitivity solve (:func:`rvdyn.te.run_te`'s ``max_outer``: one
        linearisation from a warm start); it enters the key (not the neighbourhood's).
    """

    case: Case
    solver: str
    steps: int
    revolutions: float = 1.0
    law: ContactLaw = field(default_factory=ContactLaw)
    theta_in_deg: tuple[float, ...] | None = None
    max_outer: int | None = None

    def settings(self) -> dict[str, Any]:
        """Solver settings that enter the key (besides the case); ``max_outer`` only when given (the keys of
        converged solves are unchanged)."""
        law = {"K": float(self.law.K), "n": float(self.law.n), "rigid": bool(self.law.rigid)}
        if self.law.kind != "impact":  # the law's kind reaches the worker and the key (impact keys unchanged)
            law["kind"] = self.law.kind
        d: dict[str, Any] = {"solver": self.solver, "steps": int(self.steps), "revolutions": float(self.revolutions),
                             "law": law}
        if self.theta_in_deg is not None:
            th = np.asarray(self.theta_in_deg, dtype=np.float64)
            d["steps"] = int(th.size)
            d["theta_in_deg_sha256"] = hashlib.sha256(th.tobytes()).hexdigest()
        if self.max_outer is not None:
            d["max_outer"] = int(self.max_outer)
        return d

    def key(self) -> str:
        """Cache key: sha256 (32 hex) of the case key, the settings, the code fingerprint and the version."""
        d = {"case": self.case.key(), **self.settings(), "code": code_fingerprint(self.solver),
             "version": CACHE_VERSION}
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:32]

    def neighbour_key(self) -> str:
        """Key of the job's neighbourhood for warm starts (:class:`StateStore`): sha256 (32 hex) of
        the case's design, load and direction and the settings (solver, law, angles), not its errors or model
        options: the jobs of one neighbourhood solve the same equations at the same angles for nearby parameters
        (a start of another model's coordinates is not used, :func:`rvdyn.te.run_te`)."""
        c = self.case.to_dict()
        d = {"design": c.get("design"), "load_Nm": c.get("load_Nm"), "direction": c.get("direction"),
             **self.settings()}
        d.pop("max_outer", None)  # sensitivity solves start from their converged neighbours' states
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:32]

    def to_payload(self) -> dict[str, Any]:
        """Picklable, JSON-ready description for a worker (see :func:`rvdyn.runner.solve_job`)."""
        d = {"case": self.case.to_dict(), **self.settings(), "key": self.key()}
        if self.theta_in_deg is not None:
            d["theta_in_deg"] = [float(x) for x in self.theta_in_deg]
        return d


def _checksum(payload: dict[str, Any]) -> str:
    return hashlib.sha256(json.dumps(payload, sort_keys=True, allow_nan=True).encode()).hexdigest()


def write_bytes_atomic(data: bytes, path: str | Path, fsync: bool = True) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and :func:`os.replace`."""
    path = Path(path)
    with atomic_path(path, fsync=fsync) as tmp:
        tmp.write_bytes(data)
    return path


def write_text_atomic(text: str, path: str | Path) -> Path:
    """UTF-8 text, atomically (see :func:`write_bytes_atomic`)."""
    return write_bytes_atomic(text.encode("utf-8"), path, fsync=False)


class CaseCache:
    """Directory of finished solves keyed by :meth:`Job.key`.

    Parameters
    ----------
    root : str or Path or None
        Cache folder (created on first write). ``None`` disables the cache (every lookup misses,
        nothing is written).

    Attributes
    ----------
    hits, misses, writes, rejected : int
        Counters since construction; ``rejected`` counts corrupt or partial entries ignored.
    """

    def __init__(self, root: str | Path | None) -> None:
        self.root = None if root is None else Path(root)
        self.hits = self.misses = self.writes = self.rejected = 0

    def path(self, key: str) -> Path:
        """File of an entry."""
        if self.root is None:
            raise ValueError("the cache is disabled")
        return self.root / key[:2] / f"{key}.json"

    def get(self, key: str) -> dict[str, Any] | None:
        """The stored result of a key, or None if absent, unreadable, partial or corrupt."""
        if self.root is None:
            self.misses += 1
            return None
        p = self.path(key)
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
            payload = doc["payload"]
            ok = (doc.get("version") == CACHE_VERSION and payload.get("key") == key
                  and doc.get("sha256") == _checksum(payload) and isinstance(payload.get("stats"), dict)
                  and payload.get("status") in ("ok", "failed"))
            if ok and payload["status"] == "ok":
                st = payload["stats"]
                ok = all(isinstance(st.get(k), (int, float)) and math.isfinite(st[k])
                         for k in ("pp", "mean", "mean_abs", "rms"))
        except FileNotFoundError:
            self.misses += 1
            return None
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            ok = False
        if not ok:
            self.rejected += 1
            self.misses += 1
            return None
        self.hits += 1
        return payload

    def put(self, key: str, payload: dict[str, Any]) -> Path | None:
        """Store a result (``payload['key']`` must equal ``key``); atomic. No-op when disabled."""
        if self.root is None:
            return None
        if payload.get("key") != key:
            raise ValueError(f"cache entry key {payload.get('key')!r} does not match {key!r}")
        doc = {"version": CACHE_VERSION, "sha256": _checksum(payload), "payload": payload}
        p = write_bytes_atomic(json.dumps(doc, allow_nan=True).encode("utf-8"), self.path(key))
        self.writes += 1
        return p

    def entries(self) -> list[Path]:
        """All entry files (valid or not)."""
        if self.root is None or not self.root.is_dir():
            return []
        return sorted(self.root.glob("*/*.json"))

    def counters(self) -> dict[str, int]:
        """``hits, misses, writes, rejected``."""
        return {"hits": self.hits, "misses": self.misses, "writes": self.writes, "rejected": self.rejected}


class StateStore:
    """Converged solver states of this process for warm starts (:attr:`rvdyn.te.TEResult.state`), one per
    neighbourhood (:meth:`rvdyn.cache.Job.neighbour_key`: the same design, load, direction, solver, law and
    angles, any errors and model options), the newest replacing the older; the least recently used
    neighbourhoods dropped first beyond ``max_bytes``.

    Parameters
    ----------
    max_bytes : int
        Budget, bytes (>= 0; each state counts its array's bytes).
    """

    def __init__(self, max_bytes: int) -> None:
        if isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, np.integer)) or max_bytes < 0:
            raise ValueError(f"warm_bytes {max_bytes!r} must be an integer >= 0")
        self.max_bytes = int(max_bytes)
        self._d: OrderedDict[str, np.ndarray] = OrderedDict()
        self.bytes = self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._d)

    def __contains__(self, key: str) -> bool:
        return key in self._d

    def get(self, key: str) -> np.ndarray | None:
        """The newest state of a neighbourhood (read-only, now the most recently used), or None."""
        x = self._d.get(key)
        if x is None:
            self.misses += 1
            return None
        self._d.move_to_end(key)
        self.hits += 1
        return x

    def peek(self, key: str) -> np.ndarray | None:
        """The state kept under ``key`` (read-only), or None, without counting a hit or a miss."""
        return self._d.get(key)

    def put(self, key: str, state: np.ndarray) -> None:
        """Keep a state (a read-only float64 copy) as its neighbourhood's newest; drop the oldest beyond the budget."""
        x = state if (isinstance(state, np.ndarray) and state.dtype == np.float64
                      and not state.flags.writeable) else np.array(state, dtype=np.float64)
        x.setflags(write=False)
        old = self._d.pop(key, None)
        if old is not None:
            self.bytes -= old.nbytes
        if x.nbytes > self.max_bytes:
            return
        self._d[key] = x
        self.bytes += x.nbytes
        while self.bytes > self.max_bytes:
            self.bytes -= self._d.popitem(last=False)[1].nbytes

    def discard(self, key: str) -> None:
        """Forget the state kept under ``key`` (nothing if none)."""
        old = self._d.pop(key, None)
        if old is not None:
            self.bytes -= old.nbytes

    def clear(self) -> None:
        """Forget every state."""
        self._d.clear()
        self.bytes = 0
