"""The built-in demo: simulator → virtual bus → live loop → virtual bus → decoded display."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, TextIO

from .busio import frame_to_message, message_to_frame, open_bus
from .codec import OutputCodec, load_databases
from .config import Config
from .loop import serve
from .pipeline import Pipeline
from .sim_frames import simulate_frames


@dataclass
class DemoResult:
    scenario: str
    final_status: str
    mu_max: float
    truth_mu_max: float


@dataclass
class _Listener:
    """The demo's view of the estimate frames on the virtual channel: the newest one decoded."""

    bus: Any
    codec: OutputCodec
    last: dict[str, Any] | None = None
    last_time_s: float = float("nan")   # the newest estimate's input time (the frame's timestamp)

    def read_one(self, timeout: float = 0.0) -> bool:
        """Read one frame (waiting up to `timeout`); False if none came."""
        msg = self.bus.recv(timeout=timeout)
        if msg is None:
            return False
        decoded = self.codec.decode_output(message_to_frame(msg))
        if decoded is not None:
            self.last, self.last_time_s = decoded, msg.timestamp
        return True

    def drain(self, timeout: float = 0.0) -> dict[str, Any] | None:
        """Read every estimate frame waiting (each wait up to `timeout`); the newest decoded one."""
        while self.read_one(timeout):
            pass
        return self.last

    def forget(self) -> None:
        """Drop what was read so far: a new scenario's rows show only its own estimates."""
        self.drain()
        self.last, self.last_time_s = None, float("nan")


def run_demo(
    config: Config,
    scenarios: list[str],
    *,
    pace: float = 4.0,
    seed: int = 0,
    channel: str = "frictiond-demo",
    out: TextIO | None = None,
) -> list[DemoResult]:
    pipeline = Pipeline(config)
    daemon_bus = open_bus("virtual", channel, pipeline.input_codec.input_ids, preserve_timestamps=True)
    vehicle_bus = open_bus("virtual", channel, None, preserve_timestamps=True)
    listener_bus = open_bus("virtual", channel, [pipeline.output_codec.estimate_id], preserve_timestamps=True)
    listener = _Listener(listener_bus, OutputCodec(load_databases([config.can.output_dbc], strict=True)))
    stop = threading.Event()
    loop = threading.Thread(target=serve, args=(daemon_bus, pipeline, stop), name="frictiond-loop", daemon=True)
    loop.start()
    results = []
    try:
        t0 = time.time()
        for k, name in enumerate(scenarios):
            frames, sim = simulate_frames(config, name, seed=seed + k)
            if out:
                print(f"\n== {name}: {sim.scenario.description}", file=out)
                print(f"{'t [s]':>6s} {'v [m/s]':>7s} {'status':12s} {'MuMax':>6s} {'conf':>5s} {'truth':>6s}", file=out)
            listener.forget()
            _play(frames, sim.truth, vehicle_bus, listener, pace, t0 + k * 100.0, out)
            last_decoded = listener.drain(timeout=0.05)   # (`_play` waited for the daemon's last answer)
            truth = sim.truth
            end_truth = truth.at(truth.time_s[-1] if hasattr(truth, "time_s") else 1e9)
            if last_decoded is not None:
                results.append(
                    DemoResult(name, str(last_decoded["EstimatorStatus"]), float(last_decoded["MuMax"]),
                               float(end_truth["mu_max"]))
                )
    finally:
        stop.set()
        loop.join(timeout=2.0)
        for bus in (daemon_bus, vehicle_bus, listener_bus):
            bus.shutdown()
    return results


def _play(frames: list[Any], truth: Any, vehicle_bus: Any, listener: _Listener, pace: float, t_start: float,
          out: TextIO | None) -> None:
    """Send one scenario's frames at `pace` × real time, stamped from `t_start`, printing the
    newest estimate beside the truth at that estimate's own time, every 0.25 s of the scenario
    (the daemon may be behind the frames sent: the truth at the newest frame sent is not what
    the estimate had seen), and on until the daemon has answered the last frame."""
    base = frames[0].time_s
    start_wall = time.time()
    last_print = -1.0
    for frame in frames:
        sim_t = frame.time_s - base
        delay = start_wall + sim_t / pace - time.time()
        if delay > 0:
            time.sleep(delay)
        vehicle_bus.send(frame_to_message(frame._replace(time_s=t_start + sim_t)))
        listener.drain()
        last_print = _show(listener, truth, t_start, last_print, out)
    while listener.read_one(timeout=0.1):
        last_print = _show(listener, truth, t_start, last_print, out)


def _show(listener: _Listener, truth: Any, t_start: float, last_print: float, out: TextIO | None) -> float:
    """Print the newest estimate if 0.25 s of the scenario have passed since the last one printed;
    the time of the last one printed."""
    estimate_t = listener.last_time_s - t_start
    if listener.last is None or out is None or not estimate_t - last_print >= 0.25:
        return last_print
    row, decoded = truth.at(estimate_t), listener.last
    print(f"{estimate_t:6.2f} {row['speed_mps']:7.2f} {decoded['EstimatorStatus']:12s} "
          f"{decoded['MuMax']:6.3f} {decoded['Confidence']:5.2f} {row['mu_max']:6.3f}", file=out, flush=True)
    return estimate_t
