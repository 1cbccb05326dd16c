"""The simulator's ground truth, one row every 10 ms, and the result of a run."""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from .scenarios import Scenario
from .sensors import SensorEvent
from .tyres import make_tyre

TRUTH_PERIOD_S = 0.01
WHEELS = ("fl", "fr", "rl", "rr")

# The documented columns, in CSV order (extras follow them).
CORE_COLUMNS: tuple[str, ...] = (
    ("time_s", "speed_mps")
    + tuple(f"slip_{w}" for w in WHEELS)
    + tuple(f"mu_{w}" for w in WHEELS)
    + ("mu_max",)
    + tuple(f"mu_max_{w}" for w in WHEELS)
    + ("slip_at_mu_max", "braking")
    + tuple(f"fx_{w}" for w in WHEELS)
    + tuple(f"fn_{w}" for w in WHEELS)
    + tuple(f"omega_dot_{w}" for w in WHEELS)
)
EXTRA_COLUMNS: tuple[str, ...] = (
    ("accel_long", "accel_lat", "yaw_rate")
    + tuple(f"slip_at_mu_max_{w}" for w in WHEELS)
    + tuple(f"wheel_speed_{w}" for w in WHEELS)
    + tuple(f"ground_speed_{w}" for w in WHEELS)
    + tuple(f"brake_pressure_{w}" for w in WHEELS)
    + tuple(f"abs_{w}" for w in WHEELS)
)


class Truth:
    """Per-10 ms truth rows (columns are numpy arrays).

    Columns: `time_s`, `speed_mps` (path speed at the CG), per wheel `slip_*`, utilised `mu_*` =
    F_x/F_N, the road's true peak `mu_max_*` at the wheel's ground speed and its slip
    `slip_at_mu_max_*`, `mu_max` and `slip_at_mu_max` (means over the four wheels: on a uniform
    road the road's peak, on split-μ the mean of both sides), `braking` (0/1, brake pedal applied),
    `fx_*` [N, braking positive], `fn_*` [N], `omega_dot_*` [rad/s²]; extras: `accel_long`,
    `accel_lat`, `yaw_rate`, `wheel_speed_*`, `ground_speed_*` [m/s], `brake_pressure_*` [bar],
    `abs_*` (0/1, ABS channel cycling).
    """

    def __init__(self, columns: dict[str, np.ndarray]) -> None:
        self.columns = {k: np.asarray(v, dtype=float) for k, v in columns.items()}
        self._rows: list[dict[str, float]] | None = None

    @property
    def time_s(self) -> np.ndarray:
        return self.columns["time_s"]

    @property
    def keys(self) -> tuple[str, ...]:
        return tuple(self.columns)

    def __len__(self) -> int:
        return len(self.time_s)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.columns[key]

    def __iter__(self) -> Iterator[dict[str, float]]:
        return iter(self.rows())

    def rows(self) -> list[dict[str, float]]:
        if self._rows is None:
            names = list(self.columns)
            cols = [self.columns[k].tolist() for k in names]
            self._rows = [dict(zip(names, vals)) for vals in zip(*cols)]
        return [dict(r) for r in self._rows]

    def index_at(self, t: float) -> int:
        ts = self.time_s
        i = int(np.searchsorted(ts, t))
        if i <= 0:
            return 0
        if i >= len(ts):
            return len(ts) - 1
        return i if ts[i] - t < t - ts[i - 1] else i - 1

    def at(self, t: float) -> dict[str, float]:
        """The row nearest to time `t`."""
        i = self.index_at(t)
        return {k: float(v[i]) for k, v in self.columns.items()}

    def write_csv(self, path: str | Path) -> None:
        names = list(self.columns)
        cols = [self.columns[k] for k in names]
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(names)
            for vals in zip(*(c.tolist() for c in cols)):
                w.writerow([f"{x:.7g}" for x in vals])


@dataclass
class SimulationResult:
    events: list[SensorEvent]
    truth: Truth
    scenario: Scenario
    truth_model: str = ""
    reference_speed: bool = False
    seed: int = 0
    brake_gains: tuple[float, float, float, float] = field(default=(0.0, 0.0, 0.0, 0.0))

    @property
    def duration_s(self) -> float:
        return float(self.truth.time_s[-1]) if len(self.truth) else 0.0

    def truth_csv(self, path: str | Path) -> None:
        self.truth.write_csv(path)


def build_truth(trace, family: str) -> Truth:
    """Subsample the 1 kHz trace to 10 ms rows and add the road's true peak per wheel."""
    step = max(1, int(round(TRUTH_PERIOD_S / (trace.t[1] - trace.t[0])))) if len(trace.t) > 1 else 1
    idx = np.arange(0, len(trace.t), step)
    ground = trace.ground[idx]
    surf = trace.surface[idx]
    mu_max = np.empty_like(ground)
    slip_star = np.empty_like(ground)
    for si, name in enumerate(trace.surface_names):
        model = make_tyre(family, name)
        sel = surf == si
        if sel.any():
            v = ground[sel]
            mu_max[sel] = model.mu_max(v)
            slip_star[sel] = model.slip_at_mu_max(v)
    slip = trace.slip[idx]
    fx = trace.fx[idx]
    fn = trace.fn[idx]
    cols: dict[str, np.ndarray] = {"time_s": trace.t[idx], "speed_mps": trace.v[idx]}
    for k, w in enumerate(WHEELS):
        cols[f"slip_{w}"] = slip[:, k]
    for k, w in enumerate(WHEELS):
        cols[f"mu_{w}"] = fx[:, k] / fn[:, k]
    cols["mu_max"] = mu_max.mean(axis=1)
    for k, w in enumerate(WHEELS):
        cols[f"mu_max_{w}"] = mu_max[:, k]
    cols["slip_at_mu_max"] = slip_star.mean(axis=1)
    cols["braking"] = (trace.pedal[idx] > 0.5).astype(float)
    for name, arr in (("fx", fx), ("fn", fn), ("omega_dot", trace.omega_dot[idx])):
        for k, w in enumerate(WHEELS):
            cols[f"{name}_{w}"] = arr[:, k]
    cols["accel_long"] = trace.ax[idx]
    cols["accel_lat"] = trace.ay[idx]
    cols["yaw_rate"] = trace.yaw[idx]
    for name, arr in (("slip_at_mu_max", slip_star), ("wheel_speed", trace.omega[idx]),
                      ("ground_speed", ground), ("brake_pressure", trace.pressure[idx]),
                      ("abs", trace.abs_active[idx].astype(float))):
        for k, w in enumerate(WHEELS):
            cols[f"{name}_{w}"] = arr[:, k]
    assert tuple(cols)[: len(CORE_COLUMNS)] == CORE_COLUMNS
    return Truth(cols)
