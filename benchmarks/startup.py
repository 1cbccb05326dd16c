"""Start-up: `frictiond run` from exec to READY=1 on a notify socket (systemd's protocol).

Runs the real command on python-can's virtual interface (or vcan0 when the host has it) with
NOTIFY_SOCKET pointing at a datagram socket of ours. Baseline in the same run: exec of the same
Python interpreter doing nothing (`python -c pass`).

    python benchmarks/startup.py [--runs 5]
"""
from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def time_ready(env: dict, args: list[str]) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "notify.sock")
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        sock.bind(path)
        sock.settimeout(30)
        env = dict(env, NOTIFY_SOCKET=path)
        t0 = time.perf_counter()
        proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            while True:
                data = sock.recv(4096).decode()
                if "READY=1" in data.split("\n"):
                    return time.perf_counter() - t0
        finally:
            proc.terminate()
            proc.wait(10)
            sock.close()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=5)
    args = parser.parse_args(argv)
    interface = ["--interface", "socketcan", "--channel", "vcan0"] if Path("/sys/class/net/vcan0").exists() else [
        "--interface", "virtual", "--channel", "frictiond-startup"]
    cmd = [sys.executable, "-m", "frictiond.cli.main", "run", *interface]
    env = dict(os.environ)
    ready = [time_ready(env, cmd) for _ in range(args.runs)]
    bare = []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        bare.append(time.perf_counter() - t0)
    print(f"frictiond run → READY=1: median {statistics.median(ready):.3f} s  max {max(ready):.3f} s  (n={args.runs})")
    print(f"bare interpreter start:  median {statistics.median(bare):.3f} s")
    print(f"ratio: {statistics.median(ready) / statistics.median(bare):.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
