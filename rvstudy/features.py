"""The toleranced features of a reducer drawing and the cases of their Monte Carlo draws.

A *feature* is one random variable of the stack-up: one instance of one Table 4 error type as the
drawing tolerances it (pin 17's radius, crank 1's planet offset x component, the cam of crank 0 on
disc 1, ...), or one model effect of rvdyn (``model.cam_bearing_clearance_um``). The tolerance of an
error type (:class:`rvstudy.montecarlo.Tolerance`) says by its scope which features it draws:

* ``each`` -- one feature per instance: ``Zp`` pins for the pin-wise errors (radius, pitch, radial
  position via ``pin_circle_diameter`` = twice the pin's outward shift), every crank x disc cam (phase,
  eccentricity), every crank (planet, carrier hole), every disc x hole, every disc (profile phase), and
  the single sun and pin circle;
* ``common`` -- one feature that every instance takes;
* ``default`` -- one feature on the error's default instance (paper Table 4).

Positional errors (those with a direction: ``sun_eccentricity``, ``planet_eccentricity``,
``pin_circle_offset``) have two features per instance, the x and y components of the offset (in the
frame of the conventions), each drawn from the tolerance's distribution; the case gets
``value = hypot(x, y)`` toward ``angle_deg = atan2(y, x)``.

The counts (pins, cranks, discs) come from the :class:`rvcad.params.Design` of the study (a user's
reducer with ``--reducer``), never from literals.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from rvcad.errors import ERROR_TYPES, Case
from rvcad.params import Design
from rvstudy.montecarlo import MODEL_PREFIX, Tolerance


@dataclass(frozen=True)
class Feature:
    """One random variable of the stack-up.

    Attributes
    ----------
    name : str
        Column name, e.g. ``pin_radius[pin=3]`` or ``sun_eccentricity.x``.
    tolerance : str
        Key of the tolerance that draws it (the contributor group).
    instances : tuple of dict
        Instance selectors the value applies to (``()`` for a model effect; several for scope ``common``).
    component : str
        ``value``, or ``x`` / ``y`` of a positional error.
    """

    name: str
    tolerance: str
    instances: tuple[tuple[tuple[str, int], ...], ...]
    component: str = "value"


def _instances(key: str, design: Design) -> list[dict[str, int]]:
    """Every instance of an error type on ``design`` (selector dicts)."""
    et = ERROR_TYPES[key]
    n = {"crank": design.n_cranks, "disc": design.n_discs, "hole": design.n_cranks, "pin": design.z_pins}
    keys = list(et.instance_keys)
    if not keys:
        return [{}]
    return [dict(zip(keys, combo)) for combo in itertools.product(*(range(n[k]) for k in keys))]


def features(tols: Mapping[str, Tolerance], design: Design) -> list[Feature]:
    """The features the tolerances draw on ``design``, in a fixed order (tolerance order, then instance)."""
    out: list[Feature] = []
    for key, t in tols.items():
        if t.dist == "none":
            continue
        if t.is_model:
            out.append(Feature(key, key, ()))
            continue
        et = ERROR_TYPES[key]
        allinst = _instances(key, design)
        if t.scope == "each":
            groups = [[i] for i in allinst]
        elif t.scope == "common":
            groups = [allinst]
        else:  # default instance; a default of "all pins" (pin None) is every pin
            d = {k: v for k, v in et.defaults.items() if v is not None}
            groups = [[d]] if d or not et.defaults else [allinst]
        for g in groups:
            inst = tuple(tuple(sorted(i.items())) for i in g)
            label = key if len(g) != 1 or not g[0] else key + "[" + ",".join(f"{k}={v}" for k, v in sorted(g[0].items())) + "]"
            if len(g) > 1:
                label = f"{key}[{'common' if t.scope == 'common' else 'all'}]"
            comps = ("x", "y") if et.has_angle else ("value",)
            for c in comps:
                out.append(Feature(label + (f".{c}" if c != "value" else ""), key, inst, c))
    return out


def draw(tols: Mapping[str, Tolerance], feats: list[Feature], n: int, rng: np.random.Generator) -> pd.DataFrame:
    """``n`` independent draws of every feature (one column each, in the tolerance's unit)."""
    return pd.DataFrame({f.name: tols[f.tolerance].sample(rng, n) for f in feats})


def case_dict(feats: list[Feature], row: Mapping[str, float] | np.ndarray, design: Design, name: str,
              load_Nm: float, direction: int = 1, base_model: Mapping[str, float] | None = None,
              design_dict: dict[str, Any] | None = None) -> dict[str, Any]:
    """The case JSON object of one draw (errors per instance, model effects, the study's design).

    Parameters
    ----------
    feats : list of Feature
    row : mapping or array
        The draw's value of every feature (by name, or in ``feats`` order).
    design : Design
    name : str
    load_Nm : float
        Output load torque, N m.
    direction : {1, -1}
    base_model : mapping or None
        Model options every draw carries (a model-effect feature overrides its key).
    design_dict : dict or None
        ``design.to_dict()`` made once by a caller that builds many cases (saves its cost per draw).
    """
    vals = row if isinstance(row, np.ndarray) else np.array([row[f.name] for f in feats], float)
    model: dict[str, float] = dict(base_model or {})
    per_key: dict[str, list[tuple[dict[str, int], str, float]]] = {}
    for f, v in zip(feats, vals):
        if f.tolerance.startswith(MODEL_PREFIX):
            model[f.tolerance[len(MODEL_PREFIX):]] = float(v)
            continue
        for inst in f.instances:
            per_key.setdefault(f.tolerance, []).append((dict(inst), f.component, float(v)))
    errors: dict[str, Any] = {}
    for key, items in per_key.items():
        et = ERROR_TYPES[key]
        if et.has_angle:
            xy: dict[tuple, list[float]] = {}
            for inst, comp, v in items:
                xy.setdefault(tuple(sorted(inst.items())), [0.0, 0.0])[0 if comp == "x" else 1] += v
            objs = []
            for inst, (x, y) in xy.items():
                if x == 0.0 and y == 0.0:
                    continue
                objs.append({"value": math.hypot(x, y), **dict(inst), "angle_deg": math.degrees(math.atan2(y, x))})
            if objs:
                errors[key] = objs
        elif et.pinwise:
            pins = [0.0] * design.z_pins
            for inst, _, v in items:
                pins[inst["pin"]] += v
            if any(pins):
                errors[key] = pins
        else:
            objs = [{"value": v, **inst} for inst, _, v in items if v != 0.0]
            if objs:
                errors[key] = objs
    d: dict[str, Any] = {"name": name, "design": design_dict if design_dict is not None else design.to_dict(),
                         "errors": errors, "load_Nm": float(load_Nm),
                         "direction": int(direction)}
    if model:
        d["model"] = model
    return d


def make_draw_case(feats: list[Feature], row: Any, design: Design, name: str, load_Nm: float,
                   direction: int = 1, base_model: Mapping[str, float] | None = None,
                   design_dict: dict[str, Any] | None = None) -> Case:
    """:func:`case_dict` validated into a :class:`rvcad.errors.Case` (ValueError naming the field)."""
    return Case.from_dict(case_dict(feats, row, design, name, load_Nm, direction, base_model, design_dict))


def group_columns(feats: list[Feature]) -> dict[str, list[str]]:
    """Feature columns of each tolerance (the contributor groups), in tolerance order."""
    out: dict[str, list[str]] = {}
    for f in feats:
        out.setdefault(f.tolerance, []).append(f.name)
    return out
