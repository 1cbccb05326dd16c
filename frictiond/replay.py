"""Offline replay of frames through a `Pipeline`, with a summary (shared by CLI and tests)."""
from __future__ import annotations

import csv
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Protocol

from .busio import LogFrames
from .frames import Frame
from .input_quality import LEAVE_VALID_SHARE
from .pipeline import Pipeline, PipelineStats
from .samples import WHEELS, FrictionEstimate, PhysicalSample, Status


class FrameSink(Protocol):
    def write(self, frame: Frame) -> None: ...


@dataclass
class ReplayRecorder:
    """Keeps every estimate and sample of a replay (for plots and tests)."""

    estimates: list[FrictionEstimate] = field(default_factory=list)
    samples: list[PhysicalSample] = field(default_factory=list)

    def record(self, estimate: FrictionEstimate | None, sample: PhysicalSample | None) -> None:
        if estimate is not None:
            self.estimates.append(estimate)
        if sample is not None and (not self.samples or self.samples[-1] is not sample):
            self.samples.append(sample)


@dataclass
class ReplaySummary:
    stats: PipelineStats
    first_time_s: float | None
    last_time_s: float | None
    final: FrictionEstimate | None
    trigger_period_s: float
    counter_jumps: int = 0            # alive-counter jumps on input messages (lost/repeated frames)
    repeated_triggers: int = 0        # wheel-speed frames the front end skipped (repeats, reordering)
    measured_trigger_period_s: float | None = None   # as the wheel-speed frames arrived
    period_mismatch: bool = False     # ... far from the DBC's cycle time (`FrontEnd.period_mismatch`)
    rejected: dict = field(default_factory=dict)   # input frames the plausibility gate refused, by kind
    suspect_share: float = 0.0        # ... and its share of rejected/repaired input at the end
    relaxation_m: float = 0.0         # the tyre's relaxation length learnt (`relaxation`)
    # Wheel-speed frames that gave no update: a message carrying other wheels' speeds was silent
    # around them (`wheel_speed_join`), by that message.
    unjoined: dict = field(default_factory=dict)
    # Cycle times the DBC does not give, measured from the first frames and used (`cycle_times`).
    measured_cycles: dict = field(default_factory=dict)
    # The pressure sensors too noisy for the usual ABS-release threshold, as a user is told.
    pressure_noise_note: str | None = None
    # What the body equation learnt (`BodyEquation.body_equation_note`), None without braking.
    body_equation_note: str | None = None
    # The tyres' rolling radii learnt (`RollingRadii.rolling_radius_note`), None while alike.
    rolling_radius_note: str | None = None

    @property
    def update_period_s(self) -> float:
        """The time one update stands for: the wheel-speed period as measured, else the DBC's."""
        return self.measured_trigger_period_s or self.trigger_period_s

    def status_seconds(self) -> dict[str, float]:
        period = self.update_period_s
        return {Status(s).name: n * period for s, n in sorted(self.stats.status_updates.items())}

    def format(self, truth_path: str | None = None) -> str:
        """The summary as text, a line a kind; with `truth_path`, the simulator's μ_max at the end."""
        return "\n".join(self._count_lines() + self._input_lines() + self._status_lines()
                         + self._final_lines(truth_path))

    def _count_lines(self) -> list[str]:
        """What was read, ignored, updated and written, and the time in each status."""
        s = self.stats
        span = (self.last_time_s - self.first_time_s) if self.first_time_s is not None else 0.0
        return [
            f"frames read       {s.frames_read}  ({span:.2f} s of log)",
            f"input frames      {s.input_frames}",
            f"ignored frames    {s.ignored_frames}  (not inputs"
            # the most first, in an order that does not depend on which kind came first
            + "".join(f"; {k}: {v}" for k, v in sorted(s.ignored.items(), key=lambda kv: (-kv[1], kv[0])) if v) + ")",
            f"error frames      {s.error_frames}",
            f"undecodable       {s.undecodable_total}"
            + ("" if not s.undecodable else "  (" + "; ".join(f"{k}: {v}" for k, v in s.undecodable.most_common(5)) + ")"),
            f"counter jumps     {self.counter_jumps}  (input alive counters: lost or repeated frames)"
            + (f"; {self.repeated_triggers} repeated/out-of-order wheel-speed frames skipped" if self.repeated_triggers else ""),
            f"updates           {s.updates}",
            f"frames written    {s.frames_out}",
            "time in status    " + ", ".join(f"{k} {v:.2f} s" for k, v in self.status_seconds().items()),
        ]

    def _input_lines(self) -> list[str]:
        """What the replay found of its inputs: their cycle times, the frames rejected or left
        unjoined, and what the front end learnt of the sensors and tyres."""
        lines: list[str] = []
        measured = self.measured_trigger_period_s
        if self.period_mismatch and measured is not None:
            lines.append(f"cycle time        wheel speeds every {1e3 * measured:.1f} ms, the DBC says "
                         f"{1e3 * self.trigger_period_s:.1f} ms: fix its GenMsgCycleTime (the derivative filter, "
                         "staleness limits and sample counts are sized from it)")
        if self.rejected:
            lines.append(f"rejected input    {sum(self.rejected.values())}  (implausible frames, kept from the fit"
                         + "".join(f"; {k}: {v}" for k, v in sorted(self.rejected.items(), key=lambda kv: (-kv[1], kv[0])))
                         + ")")
        if self.measured_cycles:
            lines.append("cycle times       measured, the DBC gives none: " + ", ".join(
                f"{k} {1e3 * v:.0f} ms" for k, v in sorted(self.measured_cycles.items()))
                + " (100 Hz was assumed until then; give GenMsgCycleTime in the DBC)")
        if self.unjoined:
            lines.append(f"unjoined          {sum(self.unjoined.values())} wheel-speed frames gave no update: "
                         + "; ".join(f"{k or 'another wheel-speed message'} silent around {v} of them"
                                     for k, v in sorted(self.unjoined.items()))
                         + " (its wheels' speeds not known at their instants)")
        if self.pressure_noise_note:
            lines.append(f"pressure noise    {self.pressure_noise_note}")
        if self.body_equation_note:
            lines.append(f"body equation     {self.body_equation_note}")
        if self.rolling_radius_note:
            lines.append(f"tyre radii        {self.rolling_radius_note}")
        if self.relaxation_m > 0.0:
            lines.append(f"tyre lag          relaxation length {self.relaxation_m:.2f} m learnt from the μ–slip loops, "
                         "corrected before the fit")
        return lines

    def _status_lines(self) -> list[str]:
        """The faults, and why the estimate was not VALID or no wheel's μ measured, in time."""
        s = self.stats
        lines: list[str] = []
        if s.faults:
            lines.append("faults            " + "; ".join(f"{k}: {v}" for k, v in s.faults.most_common(5)))
        if s.not_valid:
            lines.append("not VALID         " + "; ".join(
                f"{k}: {v * self.update_period_s:.2f} s" for k, v in s.not_valid.most_common())
                + f"  (VALID → CONVERGING while more than {LEAVE_VALID_SHARE:.0%} of the input frames of the last "
                "second were rejected as corrupt)")
        if s.estimator_not_valid:
            lines.append("why not VALID     " + "; ".join(
                f"{k}: {v * self.update_period_s:.2f} s" for k, v in s.estimator_not_valid.most_common(5))
                + "  (braking, by the estimator's reason)")
        if s.unmeasured:
            lines.append("no wheel μ        " + "; ".join(
                f"{v * self.update_period_s:.2f} s: {k}"
                for k, v in s.unmeasured.most_common()))
        return lines

    def _final_lines(self, truth_path: str | None) -> list[str]:
        """The final estimate and, with `truth_path`, the simulator's μ_max at the end."""
        lines: list[str] = []
        f = self.final
        if f is not None:
            wheels = " ".join(f"{w} {m:.3f}" for w, m in zip(WHEELS, f.wheel_mu_max))
            lines.append(
                f"final estimate    {f.status.name} MuMax {f.mu_max:.3f} at slip {f.slip_at_mu_max:.3f}, "
                f"theta {f.theta:.3f}, confidence {f.confidence:.2f}"
            )
            lines.append(f"per wheel MuMax   {wheels}")
        if truth_path:
            truth = read_truth_csv(truth_path)
            if truth and f is not None:
                last = truth[-1]
                lines.append(f"truth at end      mu_max {last['mu_max']:.3f}")
        return lines


def replay_frames(
    pipeline: Pipeline,
    frames: Iterable[Frame],
    sink: FrameSink | None = None,
    recorder: ReplayRecorder | None = None,
) -> ReplaySummary:
    first = last = None
    process = pipeline.process
    if recorder is not None:
        pipeline.on_estimate = recorder.record
    for frame in frames:
        if first is None:
            first = frame.time_s
        last = frame.time_s
        out = process(frame)
        if out and sink is not None:
            for f in out:
                sink.write(f)
    out = pipeline.flush()   # (the log's last wheel-speed frames, still waiting for their partners)
    if out and sink is not None:
        for f in out:
            sink.write(f)
    return ReplaySummary(
        pipeline.stats, first, last, pipeline.last_estimate, pipeline.front_end.period_of(pipeline.trigger_message),
        pipeline.input_codec.counter_jumps, pipeline.front_end.skipped_triggers,
        pipeline.front_end.measured_period_s, pipeline.front_end.period_mismatch(),
        dict(pipeline.front_end.gate.counts), pipeline.front_end.gate.suspect_share(), pipeline.relaxation.sigma_m,
        dict(pipeline.wheel_join.dropped_by) if pipeline.wheel_join is not None else {},
        dict(pipeline.measured_cycle_times),
        pipeline.front_end.pressure_noise_note(), pipeline.front_end.body_equation_note(),
        pipeline.front_end.rolling_radius_note(),
    )


def replay_log(
    pipeline: Pipeline,
    path: str | Path,
    sink: FrameSink | None = None,
    recorder: ReplayRecorder | None = None,
) -> ReplaySummary:
    """`replay_frames` over a log file, as `frictiond replay` runs it.

    The reader drops standard-ID frames of IDs the pipeline does not take before building them
    (most of a loaded bus); the pipeline counts them as it would have, and the summary's span is
    the whole log's.
    """
    frames = LogFrames(path, keep_ids=pipeline.input_codec.input_ids)
    summary = replay_frames(pipeline, frames, sink, recorder)
    pipeline.count_unrelated(frames.skipped)
    return dataclasses.replace(summary, first_time_s=frames.first_time_s, last_time_s=frames.last_time_s)


def estimates_of(config: Any, frames: Iterable[Frame]) -> tuple[Pipeline, list[FrictionEstimate]]:
    """Run a fresh pipeline over frames; the estimate of every update (for tests and benchmarks)."""
    pipeline = Pipeline(config)
    estimates: list[FrictionEstimate] = []
    pipeline.on_estimate = lambda estimate, _sample: estimates.append(estimate)
    process = pipeline.process
    for frame in frames:
        process(frame)
    pipeline.flush()
    return pipeline, estimates


def read_truth_csv(path: str | Path) -> list[dict[str, float]]:
    """Rows of a simulator truth CSV as floats (non-numeric cells become NaN)."""
    rows = []
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            parsed: dict[str, Any] = {}
            for k, v in row.items():
                try:
                    parsed[k] = float(v)
                except (TypeError, ValueError):
                    parsed[k] = math.nan
            rows.append(parsed)
    return rows
