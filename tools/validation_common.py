"""Helpers shared by the sections of docs/validation.md (tools/make_validation.py): reading the committed
result files, number and table formatting, binomial bands, held-out predictions. Needs numpy and scipy only."""
from __future__ import annotations

import json
import math
from pathlib import Path

from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
COEFFICIENTS = ["CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr"]
BAND_MASS = 0.95


def load(rel: str):
    return json.loads((ROOT / rel).read_text())


def fmt(x, digits: int = 3) -> str:
    """A number with ``digits`` significant digits, minus sign as U+2212; '—' for None or NaN."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "—"
    if x == 0:
        return "0"
    a = abs(x)
    if 1e-3 <= a < 1e5:
        s = f"{x:.{max(digits - 1 - int(math.floor(math.log10(a))), 0)}f}"
    else:
        s = f"{x:.{digits - 1}e}".replace("e-0", "e-").replace("e+0", "e")
    return s.replace("-", "−")


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def binomial_band(n: int, p: float, mass: float = BAND_MASS) -> tuple[float, float]:
    """Central ``mass`` range of Binomial(n, p)/n (the same definition as ``bayes-disc calibrate``)."""
    lo, hi = stats.binom.ppf([(1 - mass) / 2, (1 + mass) / 2], n, p)
    return float(lo / n), float(hi / n)


def outside_probability(n: int, p: float, mass: float = BAND_MASS) -> float:
    lo, hi = binomial_band(n, p, mass)
    inside = stats.binom.cdf(round(hi * n), n, p) - stats.binom.cdf(round(lo * n) - 1, n, p)
    return float(1.0 - inside)


def familywise_mass(k: int, mass: float = BAND_MASS) -> float:
    return 1.0 - (1.0 - mass) / max(k, 1)


def inside(x: float, band) -> bool:
    return band[0] - 1e-12 <= x <= band[1] + 1e-12


def fold_names(rel: str) -> list[str]:
    """The leave-one-throw-out folds under ``rel`` (one folder per left-out throw), sorted."""
    return sorted(p.name for p in (ROOT / rel).iterdir() if p.is_dir())


#: header of :func:`prediction_rows`
PREDICTION_HEADER = ["held-out throw", "channel", "unit", "RMS fixed", "RMS free", "fixed / free", "fixed fit from"]


def _start_text(start: str | None) -> str:
    """Where ``predict``'s fixed fit started (``prediction.json`` → ``start``), in words."""
    if start is None:
        return "—"
    if start.startswith("run flight "):
        return f"the run's release state of {start[len('run flight '):]}"
    return {"own": "the throw's own start", "free": "the free fit",
            "continuation": "continuation from the free fit"}.get(start, start)


def prediction_rows(rel: str) -> list[list[str]]:
    """Rows (:data:`PREDICTION_HEADER`) of every fold's ``<rel>/<fold>/out_held/prediction.json``
    (``bayes-disc predict``); a throw that was not fitted gives one row with its status and reason."""
    rows = []
    for f in fold_names(rel):
        pred = load(f"{rel}/{f}/out_held/prediction.json")
        for fl, rec in pred["flights"].items():
            if rec["status"] != "ok":
                rows.append([fl, "—", "—", "—", "—", f"{rec['status']}: {rec['reason']}", "—"])
            for ch, v in rec.get("channels", {}).items():
                rows.append([fl, ch, v["unit"], fmt(v["rms_fixed"]), fmt(v["rms_free"]),
                             f"{v['rms_fixed'] / v['rms_free']:.2f}", _start_text(rec.get("start"))])
    return rows
