"""Run the real-SocketCAN scenarios once: on the host's vcan0 if there is one, else in a UML guest.

The development and CI kernels have no CAN (see docs/vcan.md of the shared docs): there, a
user-mode Linux kernel (Debian `user-mode-linux`) boots in a few seconds with the host's root file
system (hostfs), loads can/can-raw/vcan, creates vcan0 and runs `guest.py`; its exit status goes to
a file, because the UML process's own status is not the script's.

`prepare()` writes the inputs on the host (config, logs); `guest.py` does only the live part
(canplayer, candump, cangen, frictiond run, ip link); the comparisons with `frictiond replay`
happen back on the host, where Python is fast.
"""
from __future__ import annotations

import copy
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
GUEST_SCRIPT = Path(__file__).resolve().parent / "guest.py"
XSTATE_SHIM = Path(__file__).resolve().parent / "uml_xstate_shim.c"
UML_KERNEL = "linux.uml"
GUEST_TOOLS = ("canplayer", "candump", "cangen", "ip")
APT_HINT = "apt-get install -y user-mode-linux can-utils kmod iproute2 gcc libc6-dev"
MAX_LOG_SECONDS = 6.0
STALE_CUT_S = 2.0            # BRAKE_PRESSURES stops this long after the start in stale.log
PRESSURE_ID = 0xD0


class HarnessError(RuntimeError):
    pass


def host_vcan_available() -> bool:
    """The host's own vcan0, usable for the whole suite (link down/up needs root)."""
    return Path("/sys/class/net/vcan0").exists() and os.geteuid() == 0


def uml_module_dir() -> Path | None:
    base = Path("/usr/lib/uml/modules")
    if not base.is_dir():
        return None
    versions = sorted(p for p in base.iterdir() if (p / "kernel/drivers/net/can/vcan.ko").exists())
    return versions[-1] if versions else None


def missing_tools() -> list[str]:
    missing = [t for t in GUEST_TOOLS if shutil.which(t) is None]
    if not host_vcan_available():
        if shutil.which(UML_KERNEL) is None:
            missing.append(UML_KERNEL)
        if shutil.which("insmod") is None:
            missing.append("insmod")
        if shutil.which("gcc") is None:
            missing.append("gcc")   # (builds the XSAVE shim UML needs on AVX-512/AMX hosts)
        if uml_module_dir() is None:
            missing.append("UML CAN modules")
    return missing


# ------------------------------------------------------------------------------------------ inputs
def _test_config(out: Path) -> Path:
    from frictiond.config import default_config_path

    data = yaml.safe_load(default_config_path().read_text())
    data = copy.deepcopy(data)
    data["can"].update(interface="socketcan", channel="vcan0", dbc=str(default_config_path().parent / "frictiond.dbc"))
    data.setdefault("output", {})["wheel_divider"] = 5       # lighter on the slow guest
    data.setdefault("daemon", {}).update(reconnect_max_backoff=1.0, status_interval=0.5)
    path = out / "frictiond.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _fd_config(out: Path, test_config: Path) -> Path:
    """The test config with WHEEL_SPEEDS as a 16-byte CAN FD frame and ACCELERATIONS on the 29-bit
    ID 0xC0 (fd.dbc, fd.yaml): a car whose inputs need a socket opened for FD, and 29-bit filters."""
    from frictiond.config import default_config_path

    dbc = (default_config_path().parent / "frictiond.dbc").read_text()
    edits = [('BO_ 176 WHEEL_SPEEDS: 8 VEHICLE', 'BO_ 176 WHEEL_SPEEDS: 16 VEHICLE'),
             (' SG_ WheelSpeed_RR : 48|16@1+', ' SG_ WheelSpeed_RR : 96|16@1+'),
             ('BO_ 192 ACCELERATIONS:', f'BO_ {0x80000000 | 0xC0} ACCELERATIONS:')]
    for old, new in edits:
        assert old in dbc, old
        dbc = dbc.replace(old, new)
    (out / "fd.dbc").write_text(dbc)
    data = yaml.safe_load(test_config.read_text())
    data["can"]["dbc"] = str(out / "fd.dbc")
    path = out / "fd.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _split_config(out: Path, test_config: Path) -> Path:
    """The test config with the rear wheel speeds in a message of their own (WHEEL_SPEEDS_REAR,
    0xB1, big-endian; split.dbc, split.yaml)."""
    from frictiond.config import default_config_path

    dbc = (default_config_path().parent / "frictiond.dbc").read_text()
    rear = (' SG_ WheelSpeed_RL : 32|16@1+ (0.01,0) [0|655.35] "rad/s" FRICTIOND\n'
            ' SG_ WheelSpeed_RR : 48|16@1+ (0.01,0) [0|655.35] "rad/s" FRICTIOND\n')
    assert rear in dbc
    dbc = dbc.replace(rear, '\nBO_ 177 WHEEL_SPEEDS_REAR: 4 VEHICLE\n'
                            ' SG_ WheelSpeed_RL : 7|16@0+ (0.01,0) [0|655.35] "rad/s" FRICTIOND\n'
                            ' SG_ WheelSpeed_RR : 23|16@0+ (0.01,0) [0|655.35] "rad/s" FRICTIOND\n')
    dbc = dbc.replace('BA_ "GenMsgCycleTime" BO_ 176 10;', 'BA_ "GenMsgCycleTime" BO_ 176 10;\nBA_ "GenMsgCycleTime" BO_ 177 10;')
    (out / "split.dbc").write_text(dbc)
    data = yaml.safe_load(test_config.read_text())
    data["can"]["dbc"] = str(out / "split.dbc")
    for wheel in ("rl", "rr"):
        data["signals"][f"wheel_speed_{wheel}"]["message"] = "WHEEL_SPEEDS_REAR"
    path = out / "split.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _braking_frames(config) -> tuple[list, str]:
    """The simulator's dry braking if it is there, else the synthetic drive; a few seconds."""
    try:
        from frictiond.sim_frames import simulate_frames

        frames, _ = simulate_frames(config, "dry", seed=0, time_offset_s=1000.0)
        source = "simulator dry"
    except Exception:  # noqa: BLE001 - simulator missing or being rewritten: use the synthetic drive
        from .synth import braking_frames

        frames = list(braking_frames(config, duration_s=4.0))
        source = "synthetic"
    if frames:
        t0 = frames[0].time_s
        frames = [f for f in frames if f.time_s - t0 <= MAX_LOG_SECONDS]
    return frames, source


def prepare(out: Path) -> dict:
    """Config and logs for the guest; returns what was prepared."""
    from frictiond.busio import LogWriter
    from frictiond.config import load_config

    out.mkdir(parents=True, exist_ok=True)
    cfg_path = _test_config(out)
    config = load_config(cfg_path)
    frames, source = _braking_frames(config)
    t0 = frames[0].time_s
    with LogWriter(out / "braking.log") as w:
        w.write_all(frames)
    with LogWriter(out / "stale.log") as w:
        w.write_all(f for f in frames if not (f.can_id == PRESSURE_ID and f.time_s - t0 > STALE_CUT_S))
    with LogWriter(out / "short.log") as w:
        w.write_all(f for f in frames if f.time_s - t0 <= 1.0)
    for name, make in (("fd", _fd_config), ("split", _split_config)):
        variant, _ = _braking_frames(load_config(make(out, cfg_path)))
        with LogWriter(out / f"{name}.log") as w:
            w.write_all(variant)
    info = {"source": source, "frames": len(frames), "seconds": frames[-1].time_s - t0, "config": str(cfg_path)}
    (out / "inputs.json").write_text(json.dumps(info))
    return info


# ------------------------------------------------------------------------------------------ running
def _guest_init(out: Path, modules: Path) -> Path:
    m = modules / "kernel"
    script = out / "guest-init.sh"
    script.write_text(f"""#!/bin/sh
# PID 1 of the user-mode Linux guest (the host's root file system through hostfs)
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin HOME=/root LANG=C.UTF-8
mount -t proc proc /proc
mount -t sysfs sys /sys
mount -t devtmpfs dev /dev 2>/dev/null
insmod {m}/net/can/can.ko
insmod {m}/net/can/can-raw.ko
insmod {m}/drivers/net/can/dev/can-dev.ko
insmod {m}/drivers/net/can/vcan.ko
ip link add dev vcan0 type vcan && ip link set vcan0 mtu 72 && ip link set up vcan0
# as on a gateway with memory to spare: frictiond asks for a 1 MiB receive buffer
echo 4194304 > /proc/sys/net/core/rmem_max
cd {REPO}
{sys.executable} {GUEST_SCRIPT} {out} > {out}/guest.log 2>&1
echo $? > {out}/guest-status
sync
halt -f
""")
    script.chmod(0o755)
    return script


def _build_xstate_shim(out: Path) -> Path:
    """The LD_PRELOAD library that lets UML run on hosts with AVX-512/AMX (see its source)."""
    lib = out / "uml_xstate_shim.so"
    subprocess.run(["gcc", "-O2", "-shared", "-fPIC", "-o", str(lib), str(XSTATE_SHIM), "-ldl"], check=True)
    return lib


def run_suite(out: Path, timeout_s: float = 290.0) -> dict:
    """Prepare, run the live part (host vcan0 or UML), and return the guest's results.json."""
    missing = missing_tools()
    if missing:
        raise HarnessError(f"missing {', '.join(missing)}: {APT_HINT}")
    prepared = prepare(out)
    started = time.monotonic()
    status_file = out / "guest-status"
    status_file.unlink(missing_ok=True)
    if host_vcan_available():
        mode = "host vcan0"
        subprocess.run(["ip", "link", "set", "up", "vcan0"], check=False)
        with open(out / "guest.log", "w") as log:
            proc = subprocess.run([sys.executable, str(GUEST_SCRIPT), str(out)], stdout=log, stderr=subprocess.STDOUT,
                                  timeout=timeout_s, cwd=REPO)
        status_file.write_text(f"{proc.returncode}\n")
    else:
        mode = "user-mode Linux"
        init = _guest_init(out, uml_module_dir())
        env = dict(os.environ, LD_PRELOAD=str(_build_xstate_shim(out)))
        with open(out / "console.log", "w") as console:
            subprocess.run(
                [UML_KERNEL, "mem=1G", "rootfstype=hostfs", "rootflags=/", "rw", f"init={init}", "con=null",
                 "con0=fd:0,fd:1"],
                stdin=subprocess.DEVNULL, stdout=console, stderr=subprocess.STDOUT, timeout=timeout_s, env=env,
            )
    elapsed = time.monotonic() - started
    if not status_file.exists():
        raise HarnessError(f"{mode}: the guest script left no exit status; see {out}/console.log and guest.log")
    status = int(status_file.read_text().strip() or "-1")
    results_file = out / "results.json"
    results = json.loads(results_file.read_text()) if results_file.exists() else {}
    results.update(mode=mode, guest_status=status, elapsed_s=elapsed, prepared=prepared, out=str(out))
    if status != 0:
        raise HarnessError(f"{mode}: guest script exited {status}; see {out}/guest.log:\n"
                           + (out / "guest.log").read_text()[-3000:])
    return results
