"""A fleet result set on disk: Parquet part-files any Parquet reader can query.

    RESULTS/fleet.json                 marks the folder as a result set (format, version)
    RESULTS/logs/part-RUN-NNNNN.parquet    one row per log (LOG_SCHEMA), error rows included
    RESULTS/stops/part-RUN-NNNNN.parquet   one row per braking stop (STOP_SCHEMA)

Each batch of finished logs is written as a stops part, then a logs part of the same name, each
to a temporary name first and renamed into place: a logs part is the record that its logs are
done (its `key` column), so a run killed at any point leaves only whole batches, and a stops
part without its logs part is an orphan that the next run deletes. Query without frictiond:

    duckdb -c "SELECT final_status, count(*) FROM 'RESULTS/stops/*.parquet' GROUP BY 1"
    pandas.read_parquet("RESULTS/logs")
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Iterable

import pyarrow as pa
import pyarrow.parquet as pq

from ..samples import Status

FORMAT_NAME = "frictiond-fleet"
FORMAT_VERSION = 1
MARKER = "fleet.json"

STATUS_COLUMNS = tuple(f"{s.name.lower()}_s" for s in Status)   # seconds in each status

_RUN_COLUMNS = [
    pa.field("path", pa.string()),               # the log as given (absolute)
    pa.field("key", pa.string()),                # path + size + mtime + config hash, hashed
    pa.field("config", pa.string()),             # config file; null for the built-in default
    pa.field("config_hash", pa.string()),        # sha256 of the config and its DBC files, 16 hex
    pa.field("frictiond_version", pa.string()),
    pa.field("estimator", pa.string()),          # estimator.kind
    pa.field("label", pa.string()),              # the run's --label (e.g. a release candidate)
]

LOG_SCHEMA = pa.schema(_RUN_COLUMNS + [
    pa.field("size_bytes", pa.int64()),
    pa.field("mtime_ns", pa.int64()),
    pa.field("frames", pa.int64()),
    pa.field("input_frames", pa.int64()),
    pa.field("updates", pa.int64()),
    pa.field("duration_s", pa.float64()),        # last − first frame time
    *[pa.field(name, pa.float64()) for name in STATUS_COLUMNS],
    pa.field("faults", pa.map_(pa.string(), pa.int64())),   # repaired/declared faults by kind
    pa.field("faults_total", pa.int64()),
    pa.field("undecodable", pa.int64()),
    pa.field("counter_jumps", pa.int64()),
    pa.field("stops", pa.int64()),
    pa.field("final_status", pa.string()),
    pa.field("final_mu_max", pa.float64()),
    pa.field("error_kind", pa.string()),         # null when the log replayed; else see run.py
    pa.field("error_message", pa.string()),
    pa.field("task_s", pa.float64()),            # wall time of the replay inside the worker
    pa.field("task_cpu_s", pa.float64()),        # its CPU time (below task_s: the core was shared)
    pa.field("worker", pa.string()),             # host:pid that ran it
])

STOP_SCHEMA = pa.schema(_RUN_COLUMNS + [
    pa.field("stop_index", pa.int32()),          # 0-based, in time order within the log
    pa.field("start_s", pa.float64()),           # log time (the log's own timestamps)
    pa.field("start_offset_s", pa.float64()),    # from the log's first frame (used to match stops)
    pa.field("end_s", pa.float64()),
    pa.field("duration_s", pa.float64()),
    pa.field("speed_start_mps", pa.float64()),
    pa.field("speed_end_mps", pa.float64()),
    pa.field("final_status", pa.string()),
    pa.field("mu_max_valid", pa.float64()),      # MuMax of the last VALID estimate; NaN if none
    pa.field("confidence", pa.float64()),
    pa.field("time_to_valid_s", pa.float64()),   # NaN if never VALID
    pa.field("valid_share", pa.float64()),
    pa.field("replay_command", pa.string()),
])


class NotAResultSet(ValueError):
    """A folder that is missing or holds no fleet result set."""


def init_results(folder: Path) -> None:
    """Create the folder layout (or accept an existing result set); NotAResultSet otherwise."""
    folder.mkdir(parents=True, exist_ok=True)
    marker = folder / MARKER
    if marker.exists():
        check_results(folder)
    elif any(folder.iterdir()):
        raise NotAResultSet(f"{folder}: exists, is not empty and is not a fleet result set "
                            f"(no {MARKER}); give a new or empty folder")
    else:
        marker.write_text(json.dumps({"format": FORMAT_NAME, "version": FORMAT_VERSION}) + "\n")
    (folder / "logs").mkdir(exist_ok=True)
    (folder / "stops").mkdir(exist_ok=True)


def check_results(folder: Path) -> None:
    """Raise NotAResultSet unless folder holds a result set of this format."""
    if not folder.is_dir():
        raise NotAResultSet(f"{folder}: no such folder")
    marker = folder / MARKER
    try:
        meta = json.loads(marker.read_text())
    except (OSError, ValueError):
        raise NotAResultSet(f"{folder}: not a fleet result set (no readable {MARKER})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise NotAResultSet(f"{folder}: {MARKER} does not describe a {FORMAT_NAME} result set")
    if meta.get("version") != FORMAT_VERSION:
        raise NotAResultSet(f"{folder}: result set format version {meta.get('version')!r}, "
                            f"this frictiond reads version {FORMAT_VERSION}")


def _parts(folder: Path, table: str) -> list[Path]:
    return sorted((folder / table).glob("part-*.parquet"))


def _write_atomic(table: pa.Table, path: Path) -> None:
    tmp = path.with_name(path.name + ".tmp")
    pq.write_table(table, tmp)
    os.replace(tmp, path)


def write_batch(folder: Path, name: str, log_rows: list[dict[str, Any]], stop_rows: list[dict[str, Any]]) -> None:
    """One batch as `stops/NAME` then `logs/NAME` (the logs part commits it, see the module doc)."""
    _write_atomic(pa.Table.from_pylist(stop_rows, schema=STOP_SCHEMA), folder / "stops" / name)
    _write_atomic(pa.Table.from_pylist(log_rows, schema=LOG_SCHEMA), folder / "logs" / name)


def clean_partial(folder: Path) -> int:
    """Delete what a killed run left: temporary files and stops parts without their logs part."""
    removed = 0
    for tmp in list((folder / "logs").glob("*.tmp")) + list((folder / "stops").glob("*.tmp")):
        tmp.unlink()
        removed += 1
    for part in _parts(folder, "stops"):
        if not (folder / "logs" / part.name).exists():
            part.unlink()
            removed += 1
    return removed


def read_table(folder: Path, table: str, columns: list[str] | None = None) -> pa.Table:
    """All rows of `logs` or `stops` in folder (an empty table of the schema if none)."""
    schema = LOG_SCHEMA if table == "logs" else STOP_SCHEMA
    parts = _parts(folder, table)
    if not parts:
        empty = schema.empty_table()
        return empty.select(columns) if columns else empty
    return pa.concat_tables([pq.read_table(p, columns=columns, schema=schema) for p in parts])


def done_keys(folder: Path) -> dict[str, str]:
    """key → path of every log recorded as done (replayed or failed) in the result set."""
    table = read_table(folder, "logs", ["key", "path"])
    return dict(zip(table.column("key").to_pylist(), table.column("path").to_pylist()))


def drop_logs(folder: Path, paths: Iterable[str]) -> int:
    """Remove every row of these log paths (an older version of a log, or another config's run),
    rewriting the parts that hold them; returns the rows removed from `logs`."""
    drop = set(paths)
    if not drop:
        return 0
    removed = 0
    for table in ("stops", "logs"):   # stops first: a crash in between leaves no orphan logs row
        for part in _parts(folder, table):
            rows = pq.read_table(part, schema=LOG_SCHEMA if table == "logs" else STOP_SCHEMA)
            keep = [p not in drop for p in rows.column("path").to_pylist()]
            if all(keep):
                continue
            if table == "logs":
                removed += keep.count(False)
            _write_atomic(rows.filter(pa.array(keep)), part)
    return removed
