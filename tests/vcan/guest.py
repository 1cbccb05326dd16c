"""The live part of the vcan suite, run where vcan0 exists (UML guest or the host): stdlib only.

Usage: guest.py OUT_DIR  (OUT_DIR holds frictiond.yaml, braking.log, stale.log, short.log from
harness.prepare). Writes per-scenario files and results.json into OUT_DIR; exit status 0 unless
the script itself broke (the verdicts are drawn on the host by tests/test_vcan.py).

Scenarios, each with a fresh `frictiond run`:
  replay    canplayer plays braking.log; candump -L records everything
  flood     the same while cangen floods another ID (lowest priority, as fast as it can)
  linkdown  short.log, `ip link set vcan0 down`, wait, up, short.log again
  stale     stale.log (BRAKE_PRESSURES stops mid-way), then the trigger stops too
  fd        fd.log (WHEEL_SPEEDS as 16-byte CAN FD frames, ACCELERATIONS on a 29-bit ID) with
            fd.yaml, as replay; needs vcan0's
            MTU at 72 (the guest sets it; a host's vcan0 without it: skipped)
  split     split.log (the rear wheel speeds in WHEEL_SPEEDS_REAR, 0xB1) with split.yaml, as replay
"""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import traceback
from pathlib import Path

PY = sys.executable
IFACE = "vcan0"


def link_packets() -> dict[str, int]:
    base = Path(f"/sys/class/net/{IFACE}/statistics")
    return {k: int((base / k).read_text()) for k in ("tx_packets", "rx_packets")}


class Daemon:
    def __init__(self, out: Path, name: str, config: str = "frictiond.yaml") -> None:
        self.name = name
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        address = f"frictiond-vcan-{name}-{os.getpid()}"
        self.sock.bind("\0" + address)
        self.sock.settimeout(90)
        env = dict(os.environ, NOTIFY_SOCKET="@" + address, PYTHONUNBUFFERED="1")
        self.err_path = out / f"{name}-daemon.err"
        self.err = open(self.err_path, "w")
        started = time.monotonic()
        self.proc = subprocess.Popen(
            [PY, "-m", "frictiond.cli.main", "-v", "run", "--config", str(out / config),
             "--estimate-log", str(out / f"{name}-est.log")],
            stderr=self.err, stdout=self.err, env=env,
        )
        self.messages: list[str] = []
        while not any(m.startswith("READY=1") for m in self.messages):
            self.messages.append(self.sock.recv(4096).decode())
        self.ready_s = time.monotonic() - started
        # Drain as systemd does: a unix datagram queue holds only ~10 messages, and STATUS
        # every 0.5 s over a long play would fill it and lose STOPPING.
        self.sock.settimeout(0.2)
        self._draining = True
        self._drainer = threading.Thread(target=self._drain, daemon=True)
        self._drainer.start()

    def _drain(self) -> None:
        while self._draining:
            try:
                self.messages.append(self.sock.recv(4096).decode())
            except (socket.timeout, BlockingIOError):
                continue
            except OSError:
                return

    def wait_idle(self, limit_s: float = 90.0) -> float:
        """Wait until frictiond has worked through what the kernel queued for it.

        The guest's one slow CPU (every system call is a ptrace round trip on a virtualised host)
        cannot always keep pace with canplayer and candump; the socket's receive buffer holds the
        backlog, its frames keep their arrival timestamps, and frictiond catches up. Idle means a
        STATUS, sent after this call began, that counts no frames over its interval.
        """
        started = time.monotonic()
        seen = len(self.messages)
        while time.monotonic() - started < limit_s:
            fresh = self.messages[seen:]
            if any(m.startswith("STATUS=") and " 0 frames/s" in m for m in fresh):
                break
            time.sleep(0.1)
        return time.monotonic() - started

    def alive(self) -> bool:
        return self.proc.poll() is None

    def stop(self) -> int:
        self.proc.send_signal(signal.SIGTERM)
        rc = self.proc.wait(60)
        time.sleep(0.5)              # the last datagrams reach the drainer
        self._draining = False
        self._drainer.join(2)
        self.sock.close()
        self.err.close()
        return rc

    def summary(self, rc: int) -> dict:
        return {"rc": rc, "ready_s": self.ready_s, "notify": self.messages}


class Candump:
    def __init__(self, out: Path, name: str, filters: str = "") -> None:
        self.path = out / f"{name}-capture.log"
        self.fh = open(self.path, "w")
        # the same 1 MiB receive buffer frictiond asks for (`busio.RECEIVE_BUFFER_BYTES`; not
        # imported: python-can's import costs seconds in the guest): at the default (about 300
        # frames) a stall of the guest's one CPU drops frames from the capture, not from the bus
        self.proc = subprocess.Popen(["candump", "-L", "-r", str(1 << 20), IFACE + filters], stdout=self.fh)
        time.sleep(0.2)

    def stop(self) -> None:
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.fh.close()


def play(log: Path) -> float:
    started = time.monotonic()
    # On a car the sender is another ECU with a CPU of its own; in the guest it shares one slow CPU
    # with frictiond and candump. Real-time priority keeps its frames on their cycle: starved, it
    # sent late frames back to back, which frictiond rightly refuses as a second sender's.
    subprocess.run(["chrt", "-f", "50", "canplayer", "-I", str(log), f"{IFACE}=can0"], check=True)
    return time.monotonic() - started


def recorded_play(out: Path, name: str, log: str, config: str = "frictiond.yaml") -> dict:
    """A fresh daemon and candump while canplayer plays `log`: the scenario's summary."""
    dump = Candump(out, name)
    d = Daemon(out, name, config)
    time.sleep(0.3)
    played = play(out / log)
    d.wait_idle()
    rc = d.stop()
    dump.stop()
    return {**d.summary(rc), "play_s": played}


def scenario_replay(out: Path) -> dict:
    return recorded_play(out, "replay", "braking.log")


def scenario_flood(out: Path) -> dict:
    dump = Candump(out, "flood", ",123~7FF")          # everything except the flood
    d = Daemon(out, "flood")
    before = link_packets()
    # As fast as the CPU allows, at the lowest priority: the guest has one slow CPU, and a flood at
    # normal priority would starve every process (frictiond's receive included), which says
    # nothing about frictiond. Reaches well over 10,000 frames/s, more than a 1 Mbit/s bus carries.
    flood = subprocess.Popen(["nice", "-n", "19", "cangen", IFACE, "-g", "0", "-I", "123", "-L", "8", "-D", "i",
                              "-p", "1"],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(0.5)
    played = play(out / "braking.log")
    d.wait_idle()
    time.sleep(2.0)            # frictiond idle while the flood goes on: the kernel filters it out
    flood.send_signal(signal.SIGINT)
    flood.wait(10)
    after = link_packets()
    rc = d.stop()
    dump.stop()
    return {**d.summary(rc), "play_s": played, "link_before": before, "link_after": after}


def scenario_linkdown(out: Path) -> dict:
    d = Daemon(out, "linkdown")
    first = play(out / "short.log")
    d.wait_idle()
    subprocess.run(["ip", "link", "set", IFACE, "down"], check=True)
    down_at = time.time()
    time.sleep(2.0)
    alive_while_down = d.alive()
    subprocess.run(["ip", "link", "set", IFACE, "up"], check=True)
    up_at = time.time()
    time.sleep(2.0)            # reconnect backoff is at most 1 s in the test config
    dump = Candump(out, "linkdown")
    second = play(out / "short.log")
    d.wait_idle()
    alive_after = d.alive()
    dump.stop()
    rc = d.stop()
    return {**d.summary(rc), "play_s": [first, second], "down_at": down_at, "up_at": up_at,
            "alive_while_down": alive_while_down, "alive_after": alive_after}


def scenario_stale(out: Path) -> dict:
    return recorded_play(out, "stale", "stale.log")


def scenario_fd(out: Path) -> dict:
    mtu = int(Path(f"/sys/class/net/{IFACE}/mtu").read_text())
    if mtu < 72:
        return {"skipped": f"{IFACE} has MTU {mtu}: no CAN FD frames (ip link set {IFACE} mtu 72)"}
    return recorded_play(out, "fd", "fd.log", "fd.yaml")


def scenario_split(out: Path) -> dict:
    return recorded_play(out, "split", "split.log", "split.yaml")


def main(out: Path) -> int:
    results: dict = {"kernel": os.uname().release, "scenarios": {}}
    t0 = time.monotonic()
    for name, fn in (("replay", scenario_replay), ("flood", scenario_flood), ("linkdown", scenario_linkdown),
                     ("stale", scenario_stale), ("fd", scenario_fd), ("split", scenario_split)):
        started = time.monotonic()
        try:
            results["scenarios"][name] = fn(out)
        except Exception:  # noqa: BLE001 - record and go on: the host decides
            results["scenarios"][name] = {"error": traceback.format_exc()}
            subprocess.run(["ip", "link", "set", IFACE, "up"], check=False)
        results["scenarios"][name]["elapsed_s"] = time.monotonic() - started
        print(f"{name}: {time.monotonic() - started:.1f} s", flush=True)
    results["total_s"] = time.monotonic() - t0
    (out / "results.json").write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
