"""Latency inside the daemon's own loop: a frame handed over by the bus → the output frames it
releases handed to the bus, for `frictiond run`'s Daemon on python-can's virtual bus. (A
WHEEL_SPEEDS frame's update runs when the pressures and the acceleration have been received up
to its time, `trigger_hold`: on the frame that brings them, or on the wheel-speed frame itself.)

Simulated ABS stops are played onto the bus at real-time pace (so the loop is idle between
frames as on a car), and the handling time of every frame that releases an update is recorded,
with the part spent in `bus.send`. As a floor, the same measurement for a loop that only decodes the frame with the
codec. In the same run: the same frames through a Pipeline back to back (the work without the
idle gaps and the bus) and at the same pace (sleeping in between, no bus), and how much slower
this machine runs a fixed workload right after sleeping than back to back.

    python benchmarks/latency.py [--scenarios dry,wet,snow] [--pace 1.0]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import threading
import time
import uuid
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import default_config, percentile  # noqa: E402

from frictiond.busio import frame_to_message, open_bus  # noqa: E402
from frictiond.daemon import Daemon, Overrides  # noqa: E402
from frictiond.pipeline import Pipeline  # noqa: E402
from frictiond.sim_frames import simulate_frames  # noqa: E402


class TimedDaemon(Daemon):
    """The real daemon, with a stopwatch around the handling of each frame that releases an update."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.latencies: list[float] = []
        self.sending: list[float] = []
        self.decode_only: list[float] = []
        self._send_s = 0.0
        self._sent = 0

    def _send(self, frames):  # type: ignore[override]
        t0 = time.perf_counter()
        super()._send(frames)
        self._send_s += time.perf_counter() - t0
        self._sent += len(frames)

    def _handle(self, msg):  # type: ignore[override]
        self._send_s, self._sent = 0.0, 0
        t0 = time.perf_counter()
        super()._handle(msg)
        elapsed = time.perf_counter() - t0
        if not self._sent:
            return
        self.latencies.append(elapsed)
        self.sending.append(self._send_s)
        # floor: what merely decoding this frame costs
        from frictiond.busio import message_to_frame

        t0 = time.perf_counter()
        self.pipeline.input_codec.decode(message_to_frame(msg))
        self.decode_only.append(time.perf_counter() - t0)


def _reference_work() -> float:
    """A fixed piece of pure-Python arithmetic (~0.3 ms): the machine's yardstick."""
    total = 0.0
    for i in range(3000):
        total += (i * 0.5) ** 0.5
    return total


def idle_penalty(period_s: float, runs: int = 300) -> tuple[float, float]:
    """How much slower the reference work runs right after the process slept for most of a bus
    period than back to back (median ratio, p99 ratio): a property of the machine (idle CPUs
    clock down and lose their caches), not of frictiond, which the daemon's latency pays too."""
    timings = {}
    for idle in (False, True):
        ts = []
        for _ in range(runs):
            if idle:
                time.sleep(period_s * 0.9)
            t0 = time.perf_counter()
            _reference_work()
            ts.append(time.perf_counter() - t0)
        timings[idle] = ts
    return (statistics.median(timings[True]) / statistics.median(timings[False]),
            percentile(timings[True], 99) / percentile(timings[False], 99))


def pipeline_alone(config, drives, pace: float | None) -> list[float]:
    """The pipeline's handling of each frame that releases an estimator update (a wheel-speed
    frame, or the partner frame it waited for: `trigger_hold`) of the same drives (µs), without
    the daemon and the bus: back to back (pace None), or at the drive's pace, sleeping in between."""
    pipeline = Pipeline(config)
    times = []
    for frames in drives:
        base, start = frames[0].time_s, time.perf_counter()
        for f in frames:
            if pace is not None:
                delay = (f.time_s - base) / pace - (time.perf_counter() - start)
                if delay > 0:
                    time.sleep(delay)
            t0 = time.perf_counter()
            if pipeline.process(f):
                times.append((time.perf_counter() - t0) * 1e6)
    return times


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenarios", default="dry,wet,snow")
    parser.add_argument("--pace", type=float, default=1.0, help="playback speed (1 = real time)")
    args = parser.parse_args(argv)
    config = default_config()
    # Simulated before the daemon starts (and freezes what exists, `Daemon._serve`): the sender
    # then only sends, and its allocations do not set off collections inside the daemon's thread.
    drives = [simulate_frames(config, name, seed=k)[0] for k, name in enumerate(args.scenarios.split(","))]
    warm = pipeline_alone(config, drives, None)
    paced = pipeline_alone(config, drives, args.pace)
    penalty = idle_penalty(0.01 / args.pace)
    channel = f"frictiond-bench-{uuid.uuid4().hex[:8]}"
    daemon = TimedDaemon(config, overrides=Overrides(interface="virtual", channel=channel), install_signals=False)
    thread = threading.Thread(target=daemon.run, daemon=True)
    thread.start()
    daemon.running.wait(10)
    vehicle = open_bus("virtual", channel, None, preserve_timestamps=True)
    try:
        for frames in drives:
            base, start = frames[0].time_s, time.perf_counter()
            for f in frames:
                delay = (f.time_s - base) / args.pace - (time.perf_counter() - start)
                if delay > 0:
                    time.sleep(delay)
                vehicle.send(frame_to_message(f._replace(time_s=time.time())))
            time.sleep(0.2)
    finally:
        daemon.request_stop()
        thread.join(10)
        vehicle.shutdown()
    lat = [v * 1e6 for v in daemon.latencies]
    send = [v * 1e6 for v in daemon.sending]
    dec = [v * 1e6 for v in daemon.decode_only]
    print(f"frames releasing an update handled: {len(lat)}")
    print(f"arrival → outputs sent: median {statistics.median(lat):7.1f} µs  p99 {percentile(lat, 99):7.1f} µs  "
          f"max {max(lat):7.1f} µs")
    print(f"  of which bus.send of the outputs: median {statistics.median(send):7.1f} µs  p99 {percentile(send, 99):7.1f} µs")
    print(f"floor (decode only):    median {statistics.median(dec):7.1f} µs  p99 {percentile(dec, 99):7.1f} µs")
    print(f"ratio median latency / decode: {statistics.median(lat) / statistics.median(dec):.1f}x; "
          f"p99 is {percentile(lat, 99) / 10_000 * 100:.1f} % of the 10 ms bus period")
    print(f"same frames back to back (Pipeline.process, no bus): median {statistics.median(warm):7.1f} µs  "
          f"p99 {percentile(warm, 99):7.1f} µs")
    print(f"same frames at the same pace (Pipeline.process, no bus): median {statistics.median(paced):7.1f} µs  "
          f"p99 {percentile(paced, 99):7.1f} µs")
    print(f"this machine after sleeping between frames: a fixed workload runs {penalty[0]:.2f}x slower "
          f"(median), {penalty[1]:.2f}x (p99) than back to back")
    return 0


if __name__ == "__main__":
    sys.exit(main())
