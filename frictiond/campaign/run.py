"""Running many stops: in parallel on the embedded Dask cluster (`frictiond.fleet.cluster`),
chunked, or sequentially (`workers=0`, for tests and reproduction); saving the rows."""
from __future__ import annotations

import json
import math
from concurrent.futures import as_completed
from pathlib import Path
from typing import Any, Callable, Sequence

from .draw import Stress
from .score import run_seeds

Row = dict[str, Any]


def chunks(seeds: Sequence[int], size: int) -> list[list[int]]:
    size = max(1, int(size))
    return [list(seeds[i:i + size]) for i in range(0, len(seeds), size)]


def run_campaign(seeds: Sequence[int], *, workers: int | None = None, chunk: int = 8, family: str | None = None,
                 scheduler: str | None = None, progress: Callable[[int, int], None] | None = None,
                 stress: Stress | None = None) -> list[Row]:
    """Rows of every seed, in seed order. `workers=0`: in this process, one after the other;
    otherwise Dask workers (`None`: one per core) or the cluster at `scheduler`. `stress`: what
    every stop sets in place of its draw (`draw.Stress`)."""
    rows: list[Row] = []
    parts = chunks(seeds, chunk)
    if workers == 0 and scheduler is None:
        for part in parts:
            rows.extend(run_seeds(part, family, stress))
            if progress:
                progress(len(rows), len(seeds))
    else:
        from ..fleet.cluster import open_executor

        with open_executor(scheduler, workers) as executor:
            futures = [executor.submit(run_seeds, part, family, stress) for part in parts]
            for future in as_completed(futures):
                rows.extend(future.result())
                if progress:
                    progress(len(rows), len(seeds))
    rows.sort(key=lambda r: r["seed"])
    return rows


def _json_safe(value: Any) -> Any:
    """inf/NaN as strings "inf"/"nan": the file stays standard JSON (pandas reads them back
    with `pd.to_numeric`)."""
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def save_rows(rows: Sequence[Row], path: Path | str, meta: dict[str, Any] | None = None) -> None:
    """.json (an object with `meta` and `rows`) or .parquet (one row per stop, needs pyarrow)."""
    path = Path(path)
    if path.suffix == ".parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pylist([dict(r) for r in rows])
        if meta:
            table = table.replace_schema_metadata({"campaign": json.dumps(meta)})
        pq.write_table(table, path)
        return
    doc = {"meta": meta or {}, "rows": [{k: _json_safe(v) for k, v in r.items()} for r in rows]}
    path.write_text(json.dumps(doc, indent=None, separators=(",", ":")) + "\n")


def load_rows(path: Path | str) -> list[Row]:
    path = Path(path)
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        return pq.read_table(path).to_pylist()
    doc = json.loads(path.read_text())
    return [{k: (float(v) if v in ("inf", "-inf", "nan") else v) for k, v in r.items()} for r in doc["rows"]]
