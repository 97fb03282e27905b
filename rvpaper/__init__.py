"""The source paper's published numbers and its factor map: a leaf module (pandas only, no project imports).

Reference: *Effect of Multifactor Interaction on the Accuracy of RV Reducers* (see ``data/README.md`` for
the citation). These are the paper's values (Tables 1, 4, 5, 6, 7, Eq. 8 and Eq. 9), read from the CSV
files in ``rvpaper/data`` (package data), so that an installed ``rv-stackup``, the test suite and the
loop need no folder outside the repository. Nothing here is a result of ours: every table of ours in a
report is computed by the run. The study (:mod:`rvstudy`), rsm's tests and the loop (:mod:`rvcalib`)
all read the paper from here.

Units follow the paper: EA in degrees, EB/EC/ED in micrometres, the response ("mean value of
transmission error") in arcminutes.
"""
from __future__ import annotations

from pathlib import Path

import pandas as pd


#: Folder of the paper's tables as CSV (package data; a verbatim copy of the project's
#: ``shared/data/paper_*.csv``, checked byte for byte by ``tests/test_stackup.py`` where that folder exists).
DATA_DIR = Path(__file__).resolve().parent / "data"

#: RSM factors of the paper (Table 5) and the Table 4 error type (``rvcad.errors`` key) each one is.
RSM_FACTORS: dict[str, str] = {
    "EA": "pin_pitch",
    "EB": "pin_circle_diameter",
    "EC": "pin_radius",
    "ED": "disc_hole_eccentricity",
}

#: Half range of each RSM factor in Table 5 (levels -h, 0, +h), in the error's unit (deg or um).
TABLE5_HALF_RANGE: dict[str, float] = {"EA": 0.06, "EB": 14.0, "EC": 7.0, "ED": 14.0}

#: Reduction stage of each Table 4 letter: B (sun) and C (planet) are the involute stage I.
STAGE: dict[str, str] = {L: ("I" if L in "BC" else "II") for L in "BCDEFGHIJKL"}

#: Paper Table 4 descriptions by letter (for tables and plots).
PAPER_DESCRIPTION: dict[str, str] = {
    "A": "none",
    "B": "eccentricity error of sun gear assembly",
    "C": "eccentricity error of involute gear assembly",
    "D": "phase error of cam segment on crankshaft",
    "E": "eccentricity error of cam segment on crankshaft",
    "F": "eccentricity error of crankshaft hole of planetary carrier",
    "G": "eccentricity error of crankshaft hole of cycloid gear (E_D)",
    "H": "circumferential position error of distribution circle of pin",
    "I": "error of pin distribution circle diameter (E_B)",
    "J": "error of pin radius (E_C)",
    "K": "phase error of cycloid gear",
    "L": "deviation of pin pitch (E_A)",
}


#: Paper R^2 and adjusted R^2 of the Table 7 fit.
R2 = 0.9779
R2_ADJ = 0.9521

#: Terms of the paper's full quadratic (Eq. 8), in its order.
EQ8_TERMS = ["Intercept", "EA", "EB", "EC", "ED", "EA:EB", "EA:EC", "EA:ED", "EB:EC", "EB:ED", "EC:ED",
             "EA^2", "EB^2", "EC^2", "ED^2"]

#: Terms the paper keeps in its simplified model, Eq. 9 (coefficients as in Eq. 8).
EQ9_TERMS = ["Intercept", "EA", "EB:EC", "EA^2", "EB^2", "EC^2", "ED^2"]

#: The paper's conclusions that the report checks, keyed by a short id.
CLAIMS = {
    "stage1_below_stage2": "stage I (involute) errors B, C influence TE less than the stage II errors (Fig. 9, Sec. 5)",
    "four_factors_obvious": "EA, EB, EC, ED have an obvious influence alone (Fig. 9, Sec. 4.2.1)",
    "model_significant": "the quadratic model is highly significant (p < 0.0001) with R2 = 0.9779, R2adj = 0.9521",
    "lack_of_fit_ns": "lack of fit is not significant (p = 0.0546 > 0.05)",
    "ea2_dominant": "EA^2 is the most significant term (F = 446.61)",
    "ebec_top_interaction": "EB:EC is the most significant interaction (F = 7.74, p = 0.0166; Sec. 4.2.4, Sec. 5)",
    "ea_main_effect": "EA dominates in every pair it appears in (Fig. 12 a-c)",
    "eq9_terms": "significant terms: EA, EB:EC, EA^2, EB^2, EC^2, ED^2 (Eq. 9)",
    "validation_close": "15 random cases: predicted and simulated values extremely close (Fig. 13)",
}


def _read(name: str, **kwargs) -> pd.DataFrame:
    return pd.read_csv(DATA_DIR / name, **kwargs)


def table5_levels() -> pd.DataFrame:
    """Paper Table 5 (``factor, meaning, unit, low, center, high``) plus the ``error`` key of each factor."""
    df = _read("paper_table5_levels.csv")
    df["error"] = [RSM_FACTORS[f] for f in df["factor"]]
    return df


def table6_runs() -> pd.DataFrame:
    """Paper Table 6: the 27 Box-Behnken runs in coded units and the response ``te_arcmin``."""
    return _read("paper_table6_bbd_runs.csv")


def table7_anova() -> pd.DataFrame:
    """Paper Table 7 indexed by ``source`` (``p`` kept as printed text, e.g. ``<0.0001``)."""
    return _read("paper_table7_anova.csv", dtype={"p": str}).set_index("source")


def eq8_coefficients() -> pd.Series:
    """Paper Eq. 8: full quadratic coefficients in actual units, indexed by term."""
    return _read("paper_eq8_coefficients_actual_units.csv").set_index("term")["coefficient"]


def eq9_coefficients() -> pd.Series:
    """Paper Eq. 9: Eq. 8's coefficients of the terms the paper keeps."""
    return eq8_coefficients().loc[EQ9_TERMS]


def p_value(text: str | float) -> float:
    """Numeric value of a printed p (``<0.0001`` -> 0.0001; blank -> NaN)."""
    if isinstance(text, float):
        return text
    t = str(text).strip()
    if not t or t.lower() == "nan":
        return float("nan")
    return float(t.lstrip("<"))
