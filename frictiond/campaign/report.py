"""The campaign's tables: targets (issue 21) with PASS/FAIL per estimator, per family, why
not VALID (the estimator's reasons, per ABS family), distributions, and the worst stops with the
command that reproduces each."""
from __future__ import annotations

import json
import math
from collections import defaultdict
from typing import Any, Callable, Sequence

import numpy as np

from .draw import Stress
from .score import CALIBRATION_LEVELS, ESTIMATORS, UTILISATION_SHOWN

Row = dict[str, Any]
MAE_OK = 0.05
MAE_OK_REL = 0.12
COVERAGE_OK = 0.80


def usable(rows: Sequence[Row]) -> list[Row]:
    return [r for r in rows if not r.get("sim_error")]


def abs_rows(rows: Sequence[Row]) -> list[Row]:
    return [r for r in usable(rows) if r["abs"] != "d-none"]


def mae_ok(r: Row, p: str) -> bool:
    mae = r[f"{p}_mae"]
    return math.isfinite(mae) and mae <= MAE_OK and mae <= MAE_OK_REL * r[f"{p}_span_truth"]


def share(rows: Sequence[Row], pred: Callable[[Row], bool]) -> float:
    return sum(1 for r in rows if pred(r)) / len(rows) if rows else math.nan


def finite_mean(values: Sequence[float]) -> float:
    v = [x for x in values if isinstance(x, (int, float)) and math.isfinite(x)]
    return float(np.mean(v)) if v else math.nan


def quantile(values: Sequence[float], q: float) -> float:
    v = [x for x in values if isinstance(x, (int, float)) and not math.isnan(x)]
    return float(np.quantile(np.array(v, dtype=float), q, method="inverted_cdf")) if v else math.nan


def false_valid_share(rows: Sequence[Row], p: str) -> float:
    valid = sum(r[f"{p}_valid"] for r in rows)
    return sum(r[f"{p}_false_valid"] for r in rows) / valid if valid else 0.0


def low_utilisation_valid(rows: Sequence[Row], p: str) -> int:
    """Stops with any VALID output though no wheel came within 80 % of its peak."""
    return sum(1 for r in usable(rows) if r[f"{p}_valid"] > 0 and r["max_utilisation"] < UTILISATION_SHOWN)


def calibration(rows: Sequence[Row], p: str, c: float) -> tuple[float, int]:
    n = sum(r[f"{p}_cal_n_{int(c * 100)}"] for r in rows)
    ok = sum(r[f"{p}_cal_ok_{int(c * 100)}"] for r in rows)
    return (ok / n if n else math.nan), n


def target_rows(rows: Sequence[Row], p: str) -> list[tuple[str, str, str, bool]]:
    """(target, value, goal, met) for estimator prefix `p`."""
    ab, allr = abs_rows(rows), usable(rows)
    no_valid = sum(1 for r in ab if not math.isfinite(r[f"{p}_mae"]))
    mean_mae = finite_mean([r[f"{p}_mae"] for r in ab])
    p90 = quantile([r[f"{p}_conv_s"] for r in ab], 0.9)
    out = [
        ("1 ABS stops MAE ≤ 0.05 and ≤ 12 %", f"{100 * share(ab, lambda r: mae_ok(r, p)):.1f} %", "≥ 95 %",
         share(ab, lambda r: mae_ok(r, p)) >= 0.95),
        ("1 mean MAE, ABS stops", f"{mean_mae:.4f} ({no_valid} w/o VALID)", "≤ 0.02",
         math.isfinite(mean_mae) and mean_mae <= 0.02),
        ("2 ABS stops VALID ≥ 80 % of span", f"{100 * share(ab, lambda r: r[f'{p}_valid_share'] >= COVERAGE_OK):.1f} %",
         "≥ 90 %", share(ab, lambda r: r[f"{p}_valid_share"] >= COVERAGE_OK) >= 0.90),
        ("2 convergence p90, ABS stops", f"{p90:.2f} s", "≤ 0.3 s", p90 <= 0.3),
        ("3 false VALID share of VALID", f"{100 * false_valid_share(allr, p):.2f} %", "≤ 0.5 %",
         false_valid_share(allr, p) <= 0.005),
        ("3 VALID with utilisation < 80 %", f"{low_utilisation_valid(allr, p)} stops", "0",
         low_utilisation_valid(allr, p) == 0),
        ("4 FAULT without injected fault", f"{sum(1 for r in allr if r[f'{p}_faults'] > 0)} stops", "0",
         all(r[f"{p}_faults"] == 0 for r in allr)),
        ("4 … of them FAULT above 2 m/s", f"{sum(1 for r in allr if r[f'{p}_faults_moving'] > 0)} stops", "0",
         all(r[f"{p}_faults_moving"] == 0 for r in allr)),
        ("4 pipeline crashes", f"{sum(1 for r in allr if r[f'{p}_crash'])} stops", "0",
         not any(r[f"{p}_crash"] for r in allr)),
    ]
    for c in CALIBRATION_LEVELS:
        ok, n = calibration(allr, p, c)
        out.append((f"5 within 10 % | conf ≥ {c:.1f}", f"{100 * ok:.1f} % of {n}" if n else "no outputs",
                    f"≥ {100 * c:.0f} %", n > 0 and ok >= c))
    return out


def format_targets(rows: Sequence[Row], title: str) -> str:
    per = {p: target_rows(rows, p) for p in ESTIMATORS}
    names = list(ESTIMATORS)
    head = f"{'target':38s} {'goal':>7s} " + " ".join(f"{ESTIMATORS[p]:>26s}" for p in names)
    lines = [f"== targets: {title} ({len(usable(rows))} stops, {len(abs_rows(rows))} with ABS) ==", head,
             "-" * len(head)]
    for k, (name, _v, goal, _ok) in enumerate(per[names[0]]):
        cells = [f"{per[p][k][1]:>20s} {'PASS' if per[p][k][3] else 'FAIL':>5s}" for p in names]
        lines.append(f"{name:38s} {goal:>7s} " + " ".join(cells))
    return "\n".join(lines)


def format_comparison(rows: Sequence[Row]) -> str:
    """Target 6: lugre-tr against the burckhardt-rls baseline on the same stops."""
    ab, allr = abs_rows(rows), usable(rows)
    lines = ["== 6: lugre-tr vs burckhardt-rls (same stops) =="]
    for p, kind in ESTIMATORS.items():
        lines.append(f"{kind:15s} mean MAE (ABS) {finite_mean([r[f'{p}_mae'] for r in ab]):.4f}   "
                     f"false VALID {100 * false_valid_share(allr, p):.2f} % "
                     f"({sum(r[f'{p}_false_valid'] for r in allr)} of {sum(r[f'{p}_valid'] for r in allr)})")
    both = [r for r in ab if math.isfinite(r["lugre_mae"]) and math.isfinite(r["rls_mae"])]
    if both:
        better = share(both, lambda r: r["lugre_mae"] < r["rls_mae"])
        lines.append(f"lugre-tr has the lower MAE on {100 * better:.0f} % of the {len(both)} ABS stops both rate")
    return "\n".join(lines)


def format_unvalid(rows: Sequence[Row]) -> str:
    """What MuMax is worth while not VALID (no target: the contract says not to trust it, but a
    consumer showing it, and the estimator's choice of what to say then, are judged by it): the
    ABS stops' outputs in the evaluated span that are not VALID, and the share within 20 % of
    the truth. Rows saved before these counts existed give none."""
    ab = abs_rows(rows)
    lines = ["== MuMax while not VALID (ABS stops, evaluated span) =="]
    for p, kind in ESTIMATORS.items():
        n = sum(r.get(f"{p}_unvalid", 0) for r in ab)
        within = sum(r.get(f"{p}_unvalid_within", 0) for r in ab)
        shown = f"{100 * within / n:.1f} % of {n} within 20 % of the truth" if n else "no counts in these rows"
        lines.append(f"{kind:15s} {shown}")
    return "\n".join(lines)


def _group_line(label: str, group: Sequence[Row]) -> str:
    cells = []
    for p in ESTIMATORS:
        cells.append(f"{finite_mean([r[f'{p}_mae'] for r in group]):6.3f} "
                     f"{100 * share(group, lambda r: mae_ok(r, p)):4.0f} "
                     f"{100 * share(group, lambda r: r[f'{p}_valid_share'] >= COVERAGE_OK):4.0f} "
                     f"{100 * false_valid_share(group, p):6.2f} "
                     f"{sum(1 for r in group if r[f'{p}_faults'] > 0):3d}")
    return f"{label:38s} {len(group):4d}  " + "  |  ".join(cells)


def format_families(rows: Sequence[Row]) -> str:
    """Per ABS family, tyre family and manoeuvre, then their crossing (ABS × tyre × manoeuvre)."""
    rows = usable(rows)
    sub = "MAE  MAE✓% cov% fV%    FLT"
    head = f"{'family':38s} {'n':>4s}  " + "  |  ".join(f"{ESTIMATORS[p] + ': ' + sub:>33s}" for p in ESTIMATORS)
    lines = ["== per family (MAE: mean over stops with VALID in span; MAE✓: ≤ 0.05 and ≤ 12 %; cov: VALID "
             "≥ 80 % of span; fV: false VALID share; FLT: stops with FAULT) ==", head, "-" * len(head)]
    for key, group_of in _FAMILY_GROUPS.items():
        groups: dict[str, list[Row]] = defaultdict(list)
        for r in rows:
            groups[group_of(r)].append(r)
        for name in sorted(groups):
            lines.append(_group_line(f"{key}={name}", groups[name]))
        lines.append("")
    groups = defaultdict(list)
    for r in rows:
        groups[r["family"]].append(r)
    for name in sorted(groups):
        lines.append(_group_line(name, groups[name]))
    return "\n".join(lines)


def _surface_class(r: Row) -> str:
    """Surface labels without the tyre family's prefix: dry/wet/snow/ice/cobblestone, joined."""
    return "|".join(s.replace("mf-", "").replace("_asphalt", "") for s in str(r["surfaces"]).split("|"))


def _grade_class(grade: float) -> str:
    """The road's grade in five classes: flat, up or down to 4 %, and steeper."""
    if grade == 0.0:
        return "flat"
    way = "up" if grade > 0.0 else "down"
    return f"{way} {'<4%' if abs(grade) < 0.04 else '>=4%'}"


def _relaxation_class(r: Row) -> str:
    """The tyre's relaxation length in three classes: none, short, and long enough (0.3 m or more)
    that at town speeds its lag smooths the force over an ABS cycle."""
    length = float(r.get("relaxation_m") or 0.0)
    return "none" if length <= 0.0 else ("<0.3m" if length < 0.3 else ">=0.3m")


# The per-family table's groupings: the draw's families, the tyre's relaxation, and the car's
# sensors where they decide what can be measured at all (with the master cylinder's pressure only,
# no wheel's brake torque is known once an ABS has released a wheel).
_FAMILY_GROUPS: dict[str, Callable[[Row], str]] = {
    "abs": lambda r: str(r["abs"]),
    "tyre": lambda r: str(r["tyre"]),
    "manoeuvre": lambda r: str(r["manoeuvre"]),
    "surfaces": _surface_class,
    "relaxation": _relaxation_class,
    "pressures": lambda r: "master-only" if r.get("master_only") else "per-wheel",
    "wheel_hz": lambda r: str(r.get("wheel_hz")),
    "wheel_messages": lambda r: str(r.get("wheel_messages", "one")),
    "cycle_times": lambda r: "in DBC" if r.get("cycle_times_in_dbc", True) else "measured",
    "grade": lambda r: _grade_class(float(r.get("grade") or 0.0)),
}


def format_peak_shown(rows: Sequence[Row], p: str = "lugre") -> str:
    """The ABS stops split by whether some wheel's slip went past its own peak slip (the truth's
    `past_peak_s`), with targets 1–2 on each part: a stop whose wheels all stayed short of their
    peaks (a slip target below it, an ABS releasing before it) bounds their height from below
    only, closely only where a flat-topped curve was used within a few % of its grip."""
    ab = [r for r in abs_rows(rows) if "past_peak_s" in r]
    lines = [f"== ABS stops by whether a wheel passed its peak ({ESTIMATORS[p]}) =="]
    if not ab:
        return "\n".join(lines + ["(rows without past_peak_s)"])
    for label, part in (("some wheel past its peak", [r for r in ab if r["past_peak_s"] > 0.0]),
                        ("every wheel short of its peak", [r for r in ab if r["past_peak_s"] <= 0.0])):
        if not part:
            lines.append(f"{label:32s} {0:5d} stops")
            continue
        any_valid = share(part, lambda r: r[f"{p}_valid"] > 0)
        covered = share(part, lambda r: r[f"{p}_valid_share"] >= COVERAGE_OK)
        false, valid = sum(r[f"{p}_false_valid"] for r in part), sum(r[f"{p}_valid"] for r in part)
        lines.append(f"{label:32s} {len(part):5d} stops ({100 * len(part) / len(ab):.0f} %): "
                     f"any VALID {100 * any_valid:.1f} %, MAE ok {100 * share(part, lambda r: mae_ok(r, p)):.1f} %, "
                     f"VALID ≥ 80 % of span {100 * covered:.1f} %, false VALID {false} of {valid}")
    return "\n".join(lines)


def format_distributions(rows: Sequence[Row]) -> str:
    ab = abs_rows(rows)
    qs = (0.1, 0.5, 0.9, 0.99, 1.0)
    head = f"{'metric (ABS stops)':34s} " + " ".join(f"{'p' + str(int(q * 100)) if q < 1 else 'max':>8s}" for q in qs)
    lines = ["== distributions ==", head]
    for p, kind in ESTIMATORS.items():
        for metric, key in (("MAE", "mae"), ("MAE rel", "mae_rel"), ("VALID share of span", "valid_share"),
                            ("convergence s", "conv_s"), ("false VALID count", "false_valid")):
            vals = [r[f"{p}_{key}"] for r in ab]
            lines.append(f"{kind + ' ' + metric:34s} " + " ".join(f"{quantile(vals, q):8.3f}" for q in qs))
    for key in ("max_utilisation", "max_slip", "sim_cpu_s", "lugre_cpu_s", "rls_cpu_s"):
        vals = [r[key] for r in usable(rows)]
        lines.append(f"{key + ' (all stops)':34s} " + " ".join(f"{quantile(vals, q):8.3f}" for q in qs))
    return "\n".join(lines)


def badness(r: Row, p: str = "lugre") -> float:
    """How badly a stop fails its targets (for ranking the worst): crashes first, then false
    VALID, VALID without the peak shown, FAULTs, MAE and missing coverage on ABS stops."""
    score = 10.0 if r[f"{p}_crash"] else 0.0
    valid = max(r[f"{p}_valid"], 1)
    score += 4.0 * r[f"{p}_false_valid"] / valid
    score += 2.0 if r[f"{p}_valid"] > 0 and r["max_utilisation"] < UTILISATION_SHOWN else 0.0
    score += 1.0 if r[f"{p}_faults"] > 0 else 0.0
    if r["abs"] != "d-none":
        mae = r[f"{p}_mae"]
        score += min(mae / max(r[f"{p}_span_truth"], 0.05), 2.0) if math.isfinite(mae) else 1.0
        score += 1.0 - r[f"{p}_valid_share"]
    return score


def reason(r: Row, p: str = "lugre") -> str:
    parts = []
    if r[f"{p}_crash"]:
        parts.append(f"crash {r[f'{p}_crash']}")
    if r[f"{p}_false_valid"]:
        parts.append(f"{r[f'{p}_false_valid']} of {r[f'{p}_valid']} VALID > 20 % off")
    if r[f"{p}_valid"] > 0 and r["max_utilisation"] < UTILISATION_SHOWN:
        parts.append(f"VALID though utilisation ≤ {r['max_utilisation']:.2f}")
    if r[f"{p}_faults"]:
        parts.append(f"{r[f'{p}_faults']} FAULT outputs")
    if r["abs"] != "d-none":
        mae = r[f"{p}_mae"]
        parts.append(f"MAE {mae:.3f} vs truth {r[f'{p}_span_truth']:.2f}" if math.isfinite(mae) else "no VALID in span")
        parts.append(f"VALID {100 * r[f'{p}_valid_share']:.0f} % of span")
        held_back = not_valid_seconds(r, p)
        if held_back:
            most = max(held_back, key=held_back.get)
            parts.append(f"held back mostly by: {most}")
    return "; ".join(parts) or "ok"


def not_valid_seconds(r: Row, p: str = "lugre") -> dict[str, float]:
    """The stop's braking time kept from VALID, by the estimator's reason (`score.not_valid_json`
    read back; {} in rows without it)."""
    return json.loads(r.get(f"{p}_not_valid") or "{}")


def format_not_valid(rows: Sequence[Row], p: str = "lugre", top: int = 4) -> str:
    """Per ABS family (master-cylinder-only cars apart), the braking time the estimator kept from
    VALID, by its reason: what holds each family back, in the estimator's own words."""
    lines = [f"== why not VALID ({ESTIMATORS[p]}: braking time kept from VALID, by the estimator's reason) =="]
    groups: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    for r in abs_rows(rows):
        label = f"{r['abs']}{' (master only)' if r.get('master_only') else ''}"
        for reason_, seconds in not_valid_seconds(r, p).items():
            groups[label][reason_] += seconds
    for label in sorted(groups):
        total = sum(groups[label].values())
        ranked = sorted(groups[label].items(), key=lambda kv: -kv[1])[:top]
        lines.append(f"{label:26s} {total:8.1f} s  " + "; ".join(f"{k} {100 * v / total:.0f} %" for k, v in ranked))
    return "\n".join(lines)


def reproduce_command(r: Row, family: str | None = None, stress: Stress | None = None) -> str:
    fam = f" --family {family}" if family else ""
    flags = stress.flags() if stress is not None else ""
    return f"python benchmarks/campaign.py --reproduce {r['seed']}{fam}{flags} --write-log /tmp/s{r['seed']}"


def format_worst(rows: Sequence[Row], n: int, family: str | None = None, p: str = "lugre",
                 stress: Stress | None = None) -> str:
    ranked = sorted(usable(rows), key=lambda r: -badness(r, p))[:n]
    lines = [f"== worst {len(ranked)} stops for {ESTIMATORS[p]} =="]
    for r in ranked:
        lines.append(f"seed {r['seed']:>8d}  {r['family']:34s} {r['surfaces']:28s} {r['speed0_kmh']:5.0f} km/h  "
                     f"{reason(r, p)}")
        lines.append(f"    {reproduce_command(r, family, stress)}")
    errors = [r for r in rows if r.get("sim_error")]
    for r in errors[:n]:
        lines.append(f"seed {r['seed']:>8d}  generator error: {r['sim_error']}")
    return "\n".join(lines)


def full_report(rows: Sequence[Row], title: str, worst: int = 15, family: str | None = None,
                stress: Stress | None = None) -> str:
    return "\n\n".join([format_targets(rows, title), format_comparison(rows), format_unvalid(rows),
                        format_families(rows), format_not_valid(rows), format_peak_shown(rows),
                        format_distributions(rows), format_worst(rows, worst, family, stress=stress)])
