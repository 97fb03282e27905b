"""The source paper's published numbers, for setting ours beside them in the report.

These are the paper's values (Tables 5, 6, 7, Eq. 8 and Eq. 9) exactly as
``shared/data/paper_*.csv`` holds them (``tests/test_stackup.py`` checks that they agree), kept in
the package so that an installed ``rv-stackup`` needs no data folder. Nothing here is a result of
ours: every table of ours in the report is computed by the run.

Units follow the paper: EA in degrees, EB/EC/ED in micrometres, the response ("mean value of
transmission error") in arcminutes.
"""
from __future__ import annotations

import io

import pandas as pd

from rvdyn.screen import RSM_FACTORS

_TABLE5 = """factor,meaning,unit,low,center,high
EA,deviation of pin pitch,deg,-0.06,0,0.06
EB,error of pin distribution circle diameter,um,-14,0,14
EC,error of pin radius,um,-7,0,7
ED,eccentricity error of crankshaft hole of cycloid gear,um,-14,0,14
"""

_TABLE6 = """run,EA,EB,EC,ED,te_arcmin
1,1,0,1,0,1.702960
2,-1,1,0,0,2.145570
3,0,1,0,1,0.582340
4,0,0,0,0,0.175502
5,0,-1,-1,0,0.306938
6,0,-1,0,-1,0.632792
7,-1,0,1,0,1.893480
8,0,-1,1,0,0.439095
9,0,0,0,0,0.104159
10,-1,0,-1,0,2.196420
11,0,0,-1,1,0.625511
12,0,0,-1,-1,0.616317
13,-1,-1,0,0,2.135760
14,1,0,0,-1,1.534670
15,1,0,-1,0,1.384840
16,0,1,-1,0,0.120106
17,1,0,0,1,1.546350
18,-1,0,0,1,2.038870
19,0,1,0,-1,0.574657
20,-1,0,0,-1,2.043050
21,0,-1,0,1,0.633850
22,0,1,1,0,1.137310
23,0,0,1,1,0.607289
24,1,1,0,0,1.646300
25,0,0,1,-1,0.650322
26,1,-1,0,0,1.431230
27,0,0,0,0,0.104159
"""

_TABLE7 = """source,sum_sq,df,mean_sq,F,p
Model,13.44,14,0.9598,37.93,<0.0001
EA,0.8570,1,0.8570,33.86,<0.0001
EB,0.0327,1,0.0327,1.29,0.2777
EC,0.1161,1,0.1161,4.59,0.0534
ED,0.0000,1,0.0000,0.0010,0.9750
EA:EB,0.0105,1,0.0105,0.4162,0.5310
EA:EC,0.0964,1,0.0964,3.81,0.0747
EA:ED,0.0001,1,0.0001,0.0025,0.9611
EB:EC,0.1958,1,0.1958,7.74,0.0166
EB:ED,0.0000,1,0.0000,0.0004,0.9837
EC:ED,0.0007,1,0.0007,0.0269,0.8723
EA^2,11.30,1,11.30,446.61,<0.0001
EB^2,0.2500,1,0.2500,9.88,0.0085
EC^2,0.2205,1,0.2205,8.72,0.0121
ED^2,0.3442,1,0.3442,13.60,0.0031
Residual,0.3037,12,0.0253,,
Lack of fit,0.3003,10,0.0300,17.70,0.0546
Pure error,0.0034,2,0.0017,,
Cor total,13.74,26,,,
"""

_EQ8 = """term,coefficient
Intercept,0.12794
EA,-4.45389
EB,3.73e-3
EC,1.4052e-2
ED,-1.05e-4
EA:EB,6.1089e-2
EA:EC,0.369675
EA:ED,4.719e-3
EB:EC,2.258e-3
EB:ED,8.45057e-6
EC:ED,-1.33e-4
EA^2,404.36592
EB^2,1.105e-3
EC^2,4.15e-3
ED^2,1.296e-3
"""

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


def _read(text: str) -> pd.DataFrame:
    return pd.read_csv(io.StringIO(text))


def table5_levels() -> pd.DataFrame:
    """Paper Table 5 (``factor, meaning, unit, low, center, high``) plus the ``error`` key of each factor."""
    df = _read(_TABLE5)
    df["error"] = [RSM_FACTORS[f] for f in df["factor"]]
    return df


def table6_runs() -> pd.DataFrame:
    """Paper Table 6: the 27 Box-Behnken runs in coded units and the response ``te_arcmin``."""
    return _read(_TABLE6)


def table7_anova() -> pd.DataFrame:
    """Paper Table 7 indexed by ``source`` (``p`` kept as printed text, e.g. ``<0.0001``)."""
    return pd.read_csv(io.StringIO(_TABLE7), dtype={"p": str}).set_index("source")


def eq8_coefficients() -> pd.Series:
    """Paper Eq. 8: full quadratic coefficients in actual units, indexed by term."""
    return _read(_EQ8).set_index("term")["coefficient"]


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
