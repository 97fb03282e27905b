"""Model terms: parsing, naming, design matrices and polynomial algebra.

Term syntax
-----------
A model is a list of *terms*; each term is a monomial in the factors (all factors are
continuous, so every term is exactly one column of the model matrix).

* ``Intercept`` (or ``1``) -- the constant; always included by :func:`parse_terms`.
* ``EA`` -- a main (linear) effect of factor ``EA``.
* ``EA:EB`` -- a two-factor interaction; ``EA*EB`` is accepted as a synonym.
* ``EA^2`` -- a pure quadratic; ``EA**2`` is accepted as a synonym.
* Higher order terms are written the same way: ``EA^3``, ``EA:EB:EC``, ``EA^2:EB``.
* Presets expand to several terms: ``linear`` (main effects), ``2fi`` (main effects and all
  two-factor interactions), ``quadratic`` (``2fi`` plus all pure squares; the paper's Eq. 8).

Presets and single terms can be mixed, e.g. ``["quadratic", "EA^3", "EA:EB:EC"]`` is the
full quadratic plus two cubic terms; a single string may join the parts with ``+``
(``"quadratic + EA^3"``). Duplicates are dropped; names are canonicalised
(``EB:EA`` -> ``EA:EB``, ``EA:EA`` -> ``EA^2``) with factors in the model's factor order.

Canonical ordering of terms is: Intercept, then by total degree, then (within a degree)
by the order of appearance in the presets (main effects, interactions, squares), then
user-added terms in the order given.
"""

from __future__ import annotations

import itertools
import math
import re
from collections.abc import Iterable, Sequence

import numpy as np

__all__ = [
    "PRESETS",
    "INTERCEPT",
    "Monomial",
    "validate_factor_names",
    "parse_term",
    "parse_terms",
    "term_name",
    "preset_terms",
    "model_matrix",
    "contains",
    "affine_transform_matrix",
]

INTERCEPT = "Intercept"
PRESETS = ("linear", "2fi", "quadratic")

#: A monomial is a tuple of non-negative integer exponents, one per factor.
Monomial = tuple[int, ...]

_FORBIDDEN = re.compile(r"[\s:*^+()]")


def validate_factor_names(factors: Sequence[str]) -> list[str]:
    """Check factor names for use in term strings.

    Parameters
    ----------
    factors : sequence of str
        Factor (column) names.

    Returns
    -------
    list of str
        The names as a list.

    Raises
    ------
    ValueError
        If a name is empty, duplicated, equal to ``Intercept`` or contains one of the
        characters that the term syntax uses (whitespace, ``: * ^ + ( )``).
    """
    names = [str(f) for f in factors]
    if not names:
        raise ValueError("at least one factor is required")
    seen: set[str] = set()
    for name in names:
        if not name:
            raise ValueError("factor names must not be empty")
        if _FORBIDDEN.search(name):
            raise ValueError(
                f"factor name '{name}' contains a character reserved by the term syntax "
                "(whitespace, ':', '*', '^', '+', '(' or ')'); rename the column"
            )
        if name in (INTERCEPT, "1"):
            raise ValueError(f"factor name '{name}' is reserved for the constant term")
        if name in seen:
            raise ValueError(f"factor '{name}' is listed twice")
        seen.add(name)
    return names


def term_name(monomial: Monomial, factors: Sequence[str]) -> str:
    """Canonical name of a monomial, e.g. ``(1, 1, 0, 0) -> 'EA:EB'``.

    Parameters
    ----------
    monomial : tuple of int
        Exponent of each factor.
    factors : sequence of str
        Factor names in model order.

    Returns
    -------
    str
        ``Intercept`` for the zero monomial, otherwise the factors joined by ``:`` with a
        ``^k`` suffix for exponents above one.
    """
    parts = []
    for name, power in zip(factors, monomial):
        if power == 1:
            parts.append(name)
        elif power > 1:
            parts.append(f"{name}^{power}")
    return ":".join(parts) if parts else INTERCEPT


def parse_term(text: str, factors: Sequence[str]) -> Monomial:
    """Parse one term string into a monomial.

    Parameters
    ----------
    text : str
        A term such as ``EA``, ``EA:EB``, ``EA^2``, ``EA**3``, ``EA*EB*EC`` or ``Intercept``.
    factors : sequence of str
        Factor names in model order.

    Returns
    -------
    tuple of int
        Exponent per factor.

    Raises
    ------
    ValueError
        If the term names an unknown factor or has a malformed power.
    """
    s = text.strip()
    index = {name: i for i, name in enumerate(factors)}
    powers = [0] * len(factors)
    if s in (INTERCEPT, "1", "intercept", "const"):
        return tuple(powers)
    if not s:
        raise ValueError("empty term")
    s = s.replace("**", "^")
    for part in re.split(r"[:*]", s):
        part = part.strip()
        if not part:
            raise ValueError(f"term '{text}' is malformed (empty factor between ':' or '*')")
        if "^" in part:
            base, _, exp = part.partition("^")
            base = base.strip()
            try:
                k = int(exp.strip())
            except ValueError:
                raise ValueError(
                    f"term '{text}' has a non-integer power '{exp.strip()}'"
                ) from None
            if k < 1:
                raise ValueError(f"term '{text}' has a power below 1")
        else:
            base, k = part, 1
        if base not in index:
            raise ValueError(
                f"term '{text}' uses unknown factor '{base}'; factors are {list(factors)}"
            )
        powers[index[base]] += k
    return tuple(powers)


def preset_terms(preset: str, k: int) -> list[Monomial]:
    """Monomials of a preset model for ``k`` factors (without the intercept).

    Parameters
    ----------
    preset : {'linear', '2fi', 'quadratic'}
        Preset name.
    k : int
        Number of factors.

    Returns
    -------
    list of tuple of int
    """
    key = preset.strip().lower()
    aliases = {"linear": "linear", "fo": "linear", "2fi": "2fi", "twi": "2fi",
               "interaction": "2fi", "quadratic": "quadratic", "sos": "quadratic",
               "full_quadratic": "quadratic"}
    if key not in aliases:
        raise ValueError(f"unknown model preset '{preset}'; use one of {list(PRESETS)}")
    key = aliases[key]
    out: list[Monomial] = []
    for i in range(k):
        m = [0] * k
        m[i] = 1
        out.append(tuple(m))
    if key in ("2fi", "quadratic"):
        for i, j in itertools.combinations(range(k), 2):
            m = [0] * k
            m[i] = m[j] = 1
            out.append(tuple(m))
    if key == "quadratic":
        for i in range(k):
            m = [0] * k
            m[i] = 2
            out.append(tuple(m))
    return out


def parse_terms(spec: str | Iterable[str], factors: Sequence[str]) -> list[Monomial]:
    """Expand a model specification into an ordered list of unique monomials.

    Parameters
    ----------
    spec : str or iterable of str
        A preset name, a single term, a ``+``-joined string of presets/terms, or a list of
        presets/terms. See the module docstring for the syntax.
    factors : sequence of str
        Factor names in model order.

    Returns
    -------
    list of tuple of int
        The intercept first, then the terms in canonical order.
    """
    if isinstance(spec, str):
        items = [p for p in spec.split("+")]
    else:
        items = []
        for p in spec:
            items.extend(str(p).split("+"))
    items = [p.strip() for p in items if p.strip()]
    if not items:
        raise ValueError("the model has no terms")
    k = len(factors)
    collected: list[Monomial] = [tuple([0] * k)]
    for item in items:
        if item.lower() in ("linear", "fo", "2fi", "twi", "interaction", "quadratic", "sos",
                            "full_quadratic"):
            new = preset_terms(item, k)
        else:
            new = [parse_term(item, factors)]
        for m in new:
            if m not in collected:
                collected.append(m)
    # stable sort by degree keeps preset order within a degree, user terms after
    return sorted(collected, key=lambda m: sum(m))


def model_matrix(x: np.ndarray, monomials: Sequence[Monomial]) -> np.ndarray:
    """Evaluate monomials at points.

    Parameters
    ----------
    x : ndarray, shape (n, k)
        Factor values (coded or actual; the monomials do not care).
    monomials : sequence of tuple of int
        Exponents per factor.

    Returns
    -------
    ndarray, shape (n, len(monomials))
    """
    x = np.atleast_2d(np.asarray(x, dtype=float))
    cols = np.ones((x.shape[0], len(monomials)))
    for j, m in enumerate(monomials):
        for i, p in enumerate(m):
            if p:
                cols[:, j] *= x[:, i] ** p
    return cols


def contains(parent: Monomial, child: Monomial) -> bool:
    """True if ``parent`` is a proper, non-constant divisor of ``child`` (hierarchy).

    ``EA`` is contained in ``EA:EB`` and ``EA^2``; ``EA:EB`` is contained in ``EA:EB:EC``.
    """
    if parent == child or sum(parent) == 0:
        return False
    return all(p <= c for p, c in zip(parent, child))


def affine_transform_matrix(
    monomials: Sequence[Monomial], shift: np.ndarray, scale: np.ndarray
) -> tuple[list[Monomial], np.ndarray]:
    """Re-express a polynomial under the substitution ``u_i = shift_i + scale_i * v_i``.

    If ``f(u) = sum_j b_j * u^m_j``, then ``f = sum_r c_r * v^n_r`` with ``c = T @ b``.
    Coded to actual units: ``z = (x - c)/h``, i.e. ``shift = -c/h`` and ``scale = 1/h``.

    Parameters
    ----------
    monomials : sequence of tuple of int
        Monomials of the source polynomial (in ``u``).
    shift, scale : ndarray, shape (k,)
        Affine map from ``v`` to ``u``.

    Returns
    -------
    target : list of tuple of int
        Monomials in ``v`` (every source monomial first, in the same order, then any extra
        lower-order monomials the expansion creates, ordered by degree).
    T : ndarray, shape (len(target), len(monomials))
        Linear map from source to target coefficients.
    """
    shift = np.asarray(shift, dtype=float)
    scale = np.asarray(scale, dtype=float)
    expansions: list[dict[Monomial, float]] = []
    target: list[Monomial] = list(monomials)
    for m in monomials:
        # product over factors of sum_j C(p, j) shift^(p-j) scale^j v^j
        terms: dict[Monomial, float] = {tuple([0] * len(m)): 1.0}
        for i, p in enumerate(m):
            if p == 0:
                continue
            new: dict[Monomial, float] = {}
            for mono, coef in terms.items():
                for j in range(p + 1):
                    c = math.comb(p, j) * shift[i] ** (p - j) * scale[i] ** j
                    if c == 0.0:
                        continue
                    nm = list(mono)
                    nm[i] += j
                    key = tuple(nm)
                    new[key] = new.get(key, 0.0) + coef * c
            terms = new
        expansions.append(terms)
    extra = sorted({mono for e in expansions for mono in e} - set(target),
                   key=lambda m: (sum(m), tuple(-p for p in m)))
    target.extend(extra)
    pos = {m: r for r, m in enumerate(target)}
    T = np.zeros((len(target), len(monomials)))
    for j, e in enumerate(expansions):
        for mono, coef in e.items():
            T[pos[mono], j] += coef
    return target, T
