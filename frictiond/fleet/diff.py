"""Two fleet result sets compared stop by stop (two versions, or two configs, over the same logs).

Stops are matched within a log (same path) by their start from the log's first frame, nearest
first, within `start_tolerance_s`. A matched stop has *changed* when its final status differs,
when it reached VALID in one set only, when its VALID MuMax moved by more than `tolerance`, or
its time to VALID by more than `time_tolerance_s`. Stops found in one set only (added/missing)
and logs replayed in one set only, or failed in one only, are changes too. Changes are sorted
by size: status changes, added/missing stops and log differences first, then by the largest of
|ΔMuMax| / tolerance and |Δt| / time tolerance.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import results as rs

START_TOLERANCE_S = 0.5


@dataclass
class Change:
    kind: str                      # "changed", "added", "missing", "log"
    path: str
    start_offset_s: float          # NaN for a log-level change
    what: str                      # one line: what changed
    size: float                    # for sorting; inf for status/added/missing/log changes
    command: str | None            # replays the stop (B's command; A's for a missing stop)
    span: str = ""                 # the stop's span in log time


@dataclass
class DiffReport:
    changes: list[Change]
    stops_a: int
    stops_b: int
    matched: int
    logs_both: int


def _rows(folder: Path, table: str) -> list[dict[str, Any]]:
    return rs.read_table(folder, table).to_pylist()


def _nan(x: Any) -> float:
    return math.nan if x is None else float(x)


def _stop_change(a: dict, b: dict, tolerance: float, time_tolerance_s: float) -> Change | None:
    mu_a, mu_b = _nan(a["mu_max_valid"]), _nan(b["mu_max_valid"])
    t_a, t_b = _nan(a["time_to_valid_s"]), _nan(b["time_to_valid_s"])
    notes = []
    size = 0.0
    if a["final_status"] != b["final_status"]:
        notes.append(f"status {a['final_status']} → {b['final_status']}")
        size = math.inf
    if math.isnan(mu_a) != math.isnan(mu_b):
        notes.append("VALID " + ("lost" if math.isnan(mu_b) else "gained"))
        size = math.inf
    elif not math.isnan(mu_a) and abs(mu_b - mu_a) > tolerance:
        notes.append(f"MuMax {mu_a:.3f} → {mu_b:.3f} ({mu_b - mu_a:+.3f})")
        size = max(size, abs(mu_b - mu_a) / max(tolerance, 1e-9))
    if not math.isnan(t_a) and not math.isnan(t_b) and abs(t_b - t_a) > time_tolerance_s:
        notes.append(f"time to VALID {t_a:.2f} → {t_b:.2f} s ({t_b - t_a:+.2f})")
        size = max(size, abs(t_b - t_a) / max(time_tolerance_s, 1e-9))
    if not notes:
        return None
    if size == math.inf:   # still say how far MuMax moved, for the reader
        if not math.isnan(mu_a) and not math.isnan(mu_b) and not any(n.startswith("MuMax") for n in notes):
            notes.append(f"MuMax {mu_a:.3f} → {mu_b:.3f}")
    return Change("changed", b["path"], b["start_offset_s"], "; ".join(notes), size, b["replay_command"],
                  _span(b))


def _span(stop: dict) -> str:
    return f"stop {stop['stop_index']} at {stop['start_s']:.2f}–{stop['end_s']:.2f} s"


def _match(stops_a: list[dict], stops_b: list[dict], start_tolerance_s: float) -> tuple[list, list, list]:
    """(pairs, only in A, only in B) of one log's stops, nearest starts first."""
    candidates = sorted((abs(a["start_offset_s"] - b["start_offset_s"]), i, j)
                        for i, a in enumerate(stops_a) for j, b in enumerate(stops_b)
                        if abs(a["start_offset_s"] - b["start_offset_s"]) <= start_tolerance_s)
    used_a: set[int] = set()
    used_b: set[int] = set()
    pairs = []
    for _, i, j in candidates:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            pairs.append((stops_a[i], stops_b[j]))
    return (pairs, [a for i, a in enumerate(stops_a) if i not in used_a],
            [b for j, b in enumerate(stops_b) if j not in used_b])


def _log_changes(logs_a: dict[str, dict], logs_b: dict[str, dict]) -> list[Change]:
    changes = []
    for path in sorted(logs_a.keys() ^ logs_b.keys()):
        side = "A" if path in logs_a else "B"
        changes.append(Change("log", path, math.nan, f"log replayed in {side} only", math.inf, None))
    for path in sorted(logs_a.keys() & logs_b.keys()):
        kind_a, kind_b = logs_a[path]["error_kind"], logs_b[path]["error_kind"]
        if (kind_a is None) != (kind_b is None):
            failed = logs_b[path] if kind_b is not None else logs_a[path]
            changes.append(Change("log", path, math.nan, f"log failed in {'B' if kind_b else 'A'} only: "
                                  f"{failed['error_kind']}: {failed['error_message']}", math.inf, None))
    return changes


def diff_results(folder_a: Path, folder_b: Path, tolerance: float = 0.02, time_tolerance_s: float = 0.2,
                 start_tolerance_s: float = START_TOLERANCE_S) -> DiffReport:
    """Compare two result sets; NotAResultSet when either is not one."""
    rs.check_results(folder_a)
    rs.check_results(folder_b)
    logs_a = {r["path"]: r for r in _rows(folder_a, "logs")}
    logs_b = {r["path"]: r for r in _rows(folder_b, "logs")}
    by_log: dict[str, tuple[list, list]] = {}
    stops_a, stops_b = _rows(folder_a, "stops"), _rows(folder_b, "stops")
    for side, rows in ((0, stops_a), (1, stops_b)):
        for row in rows:
            by_log.setdefault(row["path"], ([], []))[side].append(row)
    changes = _log_changes(logs_a, logs_b)
    matched = 0
    both = logs_a.keys() & logs_b.keys()
    for path in sorted(by_log.keys() & both):
        pairs, only_a, only_b = _match(*by_log[path], start_tolerance_s)
        matched += len(pairs)
        for a, b in pairs:
            change = _stop_change(a, b, tolerance, time_tolerance_s)
            if change is not None:
                changes.append(change)
        for a in only_a:
            changes.append(Change("missing", path, a["start_offset_s"], f"stop found in A only ({a['final_status']})",
                                  math.inf, a["replay_command"], _span(a)))
        for b in only_b:
            changes.append(Change("added", path, b["start_offset_s"], f"stop found in B only ({b['final_status']})",
                                  math.inf, b["replay_command"], _span(b)))
    changes.sort(key=lambda c: (-c.size, c.path, 0.0 if math.isnan(c.start_offset_s) else c.start_offset_s))
    return DiffReport(changes, len(stops_a), len(stops_b), matched, len(both))


def format_report(report: DiffReport, tolerance: float, time_tolerance_s: float, limit: int | None = None) -> str:
    """The report as text: a headline, then each change with the command that replays it."""
    counts = {k: sum(c.kind == k for c in report.changes) for k in ("changed", "added", "missing", "log")}
    lines = [f"{report.logs_both} logs in both; stops: {report.stops_a} in A, {report.stops_b} in B, "
             f"{report.matched} matched; beyond tolerance (MuMax {tolerance:g}, time to VALID "
             f"{time_tolerance_s:g} s): {counts['changed']} changed, {counts['added']} added, "
             f"{counts['missing']} missing, {counts['log']} log differences"]
    shown = report.changes if limit is None else report.changes[:limit]
    for change in shown:
        where = change.path if not change.span else f"{change.path} ({change.span})"
        lines.append(f"{change.kind:8s} {where}: {change.what}")
        if change.command:
            lines.append(f"         {change.command}")
    if len(shown) < len(report.changes):
        lines.append(f"... and {len(report.changes) - len(shown)} more (--limit)")
    return "\n".join(lines)
