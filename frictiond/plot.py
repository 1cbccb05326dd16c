"""Plots of one replay (`frictiond replay … --plot FILE`): an optional extra, `pip install 'frictiond[plot]'`.

Three panels:

* `MuMax` over time, the background shaded by estimator status, with a confidence band
  (μ_max ± 2·σ from the fit covariance; where σ is unknown, a band derived from the confidence)
  and the simulator's truth when a truth CSV is given;
* per-wheel slip over time (with the truth's slip, when the CSV has it);
* the measured μ–slip samples (the front end's usable per-wheel samples) with the fitted static
  LuGre curve at the final estimate (`estimator.mu_curve`).

The format follows the file's suffix (.png, .svg, .pdf, anything matplotlib knows). Only the Agg
family of backends is used (through `Figure` directly, no pyplot state), so this works headless and
in threads. For raster formats the image is exactly `size × dpi` pixels (see `size_for_pixels`).
"""
from __future__ import annotations

import math
from pathlib import Path
from statistics import NormalDist
from typing import Any, Sequence

from .samples import WHEELS, Status

INSTALL_HINT = "pip install 'frictiond[plot]'"
DEFAULT_SIZE_IN = (12.0, 8.0)
DEFAULT_DPI = 100.0
STATUS_COLOURS = {
    Status.INIT: "#bbbbbb",
    Status.NOT_EXCITED: "#9ecae1",
    Status.CONVERGING: "#fdd49e",
    Status.VALID: "#a1d99b",
    Status.INPUT_STALE: "#dadaeb",
    Status.FAULT: "#fc9272",
}
WHEEL_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728")
CONFIDENCE_BAND = 0.10   # LugreTROptions.confidence_band's default: the confidence is P(error within this share)


def plotting_available() -> bool:
    """True when matplotlib can be imported."""
    try:
        import matplotlib  # noqa: F401
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
    except ImportError:
        return False
    return True


def supported_formats() -> dict[str, str]:
    """File suffixes (without dot) matplotlib can write, with their descriptions."""
    from matplotlib.backend_bases import FigureCanvasBase

    return dict(FigureCanvasBase.get_supported_filetypes())


def check_plot_path(path: str | Path) -> None:
    """ValueError unless the suffix names a format matplotlib writes (checked before a long replay)."""
    suffix = Path(path).suffix.lower().lstrip(".")
    formats = supported_formats()
    if suffix not in formats:
        raise ValueError(f"{path}: unknown image format {('.' + suffix) if suffix else '(no suffix)'}; "
                         f"use .png, .svg or .pdf (or one of {', '.join('.' + f for f in sorted(formats))})")


def parse_size(text: str) -> tuple[int, int]:
    """'1200x800' → (1200, 800) pixels; ValueError with a readable message otherwise."""
    parts = text.lower().replace("×", "x").split("x")
    if len(parts) != 2:
        raise ValueError(f"{text!r} is not WIDTHxHEIGHT in pixels (e.g. 1200x800)")
    try:
        w, h = int(parts[0]), int(parts[1])
    except ValueError:
        raise ValueError(f"{text!r} is not WIDTHxHEIGHT in pixels (e.g. 1200x800)") from None
    if not (100 <= w <= 20000 and 100 <= h <= 20000):
        raise ValueError(f"{text!r}: width and height must be between 100 and 20000 pixels")
    return w, h


def size_for_pixels(width_px: int, height_px: int, dpi: float = DEFAULT_DPI) -> tuple[float, float]:
    """Figure size in inches that renders to exactly `width_px` × `height_px` at `dpi`.

    Agg truncates size × dpi to whole pixels; a quarter pixel of margin keeps floating-point
    error from costing a row or column.
    """
    return (width_px + 0.25) / dpi, (height_px + 0.25) / dpi


def _finite(x: float) -> bool:
    return x is not None and math.isfinite(x)


def _band_halfwidth(estimate: Any, band: float) -> float:
    """2σ of μ_max: from the covariance when known, else from the confidence (the probability of
    a Gaussian error within `band` of μ_max: c = erf(band / (σ_rel √2)))."""
    std = getattr(estimate, "mu_max_std", math.inf)
    if _finite(std):
        return 2.0 * std
    c = estimate.confidence
    if not _finite(c) or c <= 0.0 or not _finite(estimate.mu_max):
        return math.nan
    z = NormalDist().inv_cdf(0.5 + 0.5 * min(c, 1.0 - 1e-9))
    return 2.0 * band / z * abs(estimate.mu_max)


def _status_runs(times: Sequence[float], statuses: Sequence[Status]) -> list[tuple[float, float, Status]]:
    """Contiguous (start, end, status) spans; each update's status lasts until the next update."""
    runs: list[tuple[float, float, Status]] = []
    if not times:
        return runs
    dt = 0.0
    if len(times) > 1:
        steps = sorted(b - a for a, b in zip(times, times[1:]) if b > a)
        dt = steps[len(steps) // 2] if steps else 0.0
    start = 0
    for i in range(1, len(times) + 1):
        if i == len(times) or statuses[i] != statuses[start]:
            end = times[i] if i < len(times) else times[-1] + dt
            runs.append((times[start], end, statuses[start]))
            start = i
    return runs


def _truth(truth_path: str | Path | None, t_first: float | None, t_last: float | None) -> tuple[list[dict], float, bool]:
    """Truth rows and the offset to add to their times (when the log's clock does not start at 0)."""
    if not truth_path:
        return [], 0.0, False
    from .replay import read_truth_csv

    rows = [r for r in read_truth_csv(truth_path) if _finite(r.get("time_s", math.nan))]
    if not rows or t_first is None or t_last is None:
        return rows, 0.0, False
    lo, hi = rows[0]["time_s"], rows[-1]["time_s"]
    if hi < t_first or lo > t_last:  # no overlap: the log was stamped on another clock
        return rows, t_first - lo, True
    return rows, 0.0, False


def _draw_mu(ax_mu: Any, estimates: list, band: float, truth: list | None, offset: float, shifted: bool) -> None:
    """The top panel: MuMax over time with its confidence band, the status as background, the truth."""
    from matplotlib.patches import Patch

    times = [e.time_s for e in estimates]
    final = estimates[-1] if estimates else None
    seen_status: list[Status] = []
    for start, end, status in _status_runs(times, [Status(e.status) for e in estimates]):
        ax_mu.axvspan(start, end, color=STATUS_COLOURS.get(status, "#eeeeee"), alpha=0.35, lw=0)
        if status not in seen_status:
            seen_status.append(status)
    nan = math.nan
    mu = [e.mu_max if _finite(e.mu_max) and e.status not in (Status.INIT,) else nan for e in estimates]
    half = [_band_halfwidth(e, band) if _finite(m) else nan for e, m in zip(estimates, mu)]
    lo = [m - h if _finite(h) else nan for m, h in zip(mu, half)]
    hi = [m + h if _finite(h) else nan for m, h in zip(mu, half)]
    handles = []
    if estimates:
        band = ax_mu.fill_between(times, lo, hi, color="#3182bd", alpha=0.25, lw=0, label="±2σ confidence band")
        (line,) = ax_mu.plot(times, mu, color="#08519c", lw=1.4, label="MuMax estimate")
        handles += [line, band]
    if truth and "mu_max" in truth[0]:
        (tline,) = ax_mu.plot([r["time_s"] + offset for r in truth], [r["mu_max"] for r in truth],
                              color="black", lw=1.2, ls="--",
                              label="truth" + (" (aligned to log start)" if shifted else ""))
        handles.append(tline)
    handles += [Patch(color=STATUS_COLOURS.get(s, "#eeeeee"), alpha=0.5, label=s.name) for s in seen_status]
    if handles:
        ax_mu.legend(handles=handles, loc="upper right", fontsize="small", ncol=min(4, len(handles)))
    top = max([v for v in hi + mu if _finite(v)] + [1.2])
    ax_mu.set_ylim(0.0, min(2.2, top * 1.15))
    ax_mu.set_ylabel("μ_max")
    ax_mu.set_title("road peak friction MuMax" + (f" — final {final.status.name} {final.mu_max:.3f}" if final else ""),
                    fontsize="medium")
    ax_mu.grid(True, alpha=0.3)
    if not estimates:
        ax_mu.text(0.5, 0.5, "no estimates in this replay", transform=ax_mu.transAxes, ha="center", va="center")


def _draw_slip(ax_slip: Any, samples: list, truth: list | None, offset: float, final: Any) -> None:
    """Each wheel's slip over time (and its truth), with the slip at the final MuMax."""
    st = [s.time_s for s in samples]
    for i, wheel in enumerate(WHEELS):
        if samples:
            ax_slip.plot(st, [s.slip[i] for s in samples], color=WHEEL_COLOURS[i], lw=1.0, label=wheel)
        key = f"slip_{wheel.lower()}"
        if truth and key in truth[0]:
            ax_slip.plot([r["time_s"] + offset for r in truth], [r[key] for r in truth], color=WHEEL_COLOURS[i],
                         lw=0.8, ls=":", label=f"{wheel} truth")
    if final is not None and _finite(final.slip_at_mu_max) and final.slip_at_mu_max > 0:
        ax_slip.axhline(final.slip_at_mu_max, color="grey", lw=0.8, ls="--", label="slip at MuMax")
    ax_slip.set_xlabel("time [s]")
    ax_slip.set_ylabel("slip λ")
    ax_slip.set_title("wheel slip", fontsize="medium")
    ax_slip.grid(True, alpha=0.3)
    if samples or truth:
        ax_slip.legend(loc="upper right", fontsize="x-small", ncol=2)
    else:
        ax_slip.text(0.5, 0.5, "no samples", transform=ax_slip.transAxes, ha="center", va="center")


def _draw_curve(ax_curve: Any, samples: list, estimator: Any, final: Any, rasterize: bool) -> None:
    """The usable μ–slip samples per wheel, and the fitted curve at the final estimate's speed
    with its peak."""
    max_slip = 0.0
    min_slip = 0.0
    speeds = []
    for i, wheel in enumerate(WHEELS):
        xs, ys = [], []
        for s in samples:
            if s.usable[i] and _finite(s.slip[i]) and _finite(s.mu_used[i]):
                xs.append(s.slip[i])
                ys.append(s.mu_used[i])
                speeds.append(s.speed_mps)
        if xs:
            ax_curve.scatter(xs, ys, s=4, color=WHEEL_COLOURS[i], alpha=0.35, lw=0, label=f"{wheel} samples",
                             rasterized=rasterize)
            max_slip = max(max_slip, max(xs))
            min_slip = min(min_slip, min(xs))
    if estimator is not None and final is not None and hasattr(estimator, "mu_curve"):
        import numpy as np

        # at the speed of the final estimate (the last sample), where its MuMax and peak slip hold
        speed = samples[-1].speed_mps if samples else (float(np.median(speeds)) if speeds else 20.0)
        upper = max(0.3, max_slip * 1.1, (final.slip_at_mu_max * 2.0) if _finite(final.slip_at_mu_max) else 0.0)
        grid_slip = np.linspace(min(0.0, min_slip * 1.1), min(1.0, upper), 300)
        try:
            curve = np.asarray(estimator.mu_curve(grid_slip, speed), dtype=float)
        except Exception:  # an estimator that has not fitted anything yet
            curve = None
        if curve is not None and curve.shape == grid_slip.shape and np.isfinite(curve).any():
            ax_curve.plot(grid_slip, curve, color="black", lw=1.6,
                          label=f"fitted static LuGre at {speed:.1f} m/s")
        if _finite(final.mu_max) and _finite(final.slip_at_mu_max):
            ax_curve.plot([final.slip_at_mu_max], [final.mu_max], marker="o", color="#d62728", ls="none",
                          label=f"peak {final.mu_max:.3f} at λ {final.slip_at_mu_max:.3f}")
    ax_curve.set_xlabel("slip λ")
    ax_curve.set_ylabel("μ = Fx / Fz")
    ax_curve.set_title("measured μ–slip and fitted curve", fontsize="medium")
    ax_curve.grid(True, alpha=0.3)
    if ax_curve.has_data():
        legend = ax_curve.legend(loc="lower right", fontsize="x-small")
        for handle in getattr(legend, "legend_handles", []):
            if hasattr(handle, "set_sizes"):   # scatter swatches as visible as the lines
                handle.set_sizes([16])
                handle.set_alpha(1.0)
    else:
        ax_curve.text(0.5, 0.5, "no usable samples", transform=ax_curve.transAxes, ha="center", va="center")


def plot_replay(
    recorder: Any,
    path: str | Path,
    truth_path: str | Path | None = None,
    estimator: Any = None,
    size: tuple[float, float] | None = None,
    dpi: float = DEFAULT_DPI,
    pixels: tuple[int, int] | None = None,
    title: str | None = None,
) -> Path:
    """Draw a replay (a `ReplayRecorder`) to `path`; format by suffix. Returns the path.

    `size` is in inches at `dpi`; `pixels=(w, h)` asks for an exact raster size instead.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    if pixels is not None:
        size = size_for_pixels(pixels[0], pixels[1], dpi)
    if size is None:
        size = DEFAULT_SIZE_IN
    fig = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2, height_ratios=(1.1, 1.0), hspace=0.32, wspace=0.22,
                            left=0.07, right=0.98, top=0.93, bottom=0.08)
    ax_mu = fig.add_subplot(grid[0, :])
    ax_slip = fig.add_subplot(grid[1, 0], sharex=ax_mu)
    ax_curve = fig.add_subplot(grid[1, 1])

    estimates = list(getattr(recorder, "estimates", []))
    samples = list(getattr(recorder, "samples", []))
    times = [e.time_s for e in estimates]
    t_first = times[0] if times else (samples[0].time_s if samples else None)
    t_last = times[-1] if times else (samples[-1].time_s if samples else None)
    final = estimates[-1] if estimates else None
    band = getattr(getattr(estimator, "options", None), "confidence_band", CONFIDENCE_BAND)
    if not _finite(band) or band <= 0:
        band = CONFIDENCE_BAND
    truth, offset, shifted = _truth(truth_path, t_first, t_last)

    _draw_mu(ax_mu, estimates, band, truth, offset, shifted)
    _draw_slip(ax_slip, samples, truth, offset, final)
    _draw_curve(ax_curve, samples, estimator, final,
                rasterize=path.suffix.lower() not in (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".webp"))

    if title:
        fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    return path
