"""A small sd_notify(3) client: one datagram per notification to `$NOTIFY_SOCKET`.

The protocol is stable and tiny, so frictiond carries its own instead of depending on
python-systemd: newline-separated `KEY=value` assignments sent as one `AF_UNIX` datagram to the
path in `$NOTIFY_SOCKET` (a leading `@` means Linux's abstract namespace). Without the variable
(not started by systemd with `Type=notify`) every call is a cheap no-op.
"""
from __future__ import annotations

import logging
import os
import socket
import time
from typing import Mapping

log = logging.getLogger(__name__)


def socket_address(value: str | None) -> str | bytes | None:
    """The `sendto` address for a `$NOTIFY_SOCKET` value; None when unset or unusable."""
    if not value:
        return None
    if value.startswith("@"):
        return b"\0" + value[1:].encode()
    if value.startswith("/"):
        return value
    # vsock:… and other transports are not used for system services; ignore them.
    return None


def watchdog_interval_s(environ: Mapping[str, str] | None = None, pid: int | None = None) -> float | None:
    """Seconds between `WATCHDOG=1` pings (half of `$WATCHDOG_USEC`), or None if no watchdog.

    `$WATCHDOG_PID`, when set, must name this process (a child must not ping for its parent).
    """
    env = os.environ if environ is None else environ
    usec = env.get("WATCHDOG_USEC")
    if not usec:
        return None
    wd_pid = env.get("WATCHDOG_PID")
    if wd_pid:
        try:
            if int(wd_pid) != (os.getpid() if pid is None else pid):
                return None
        except ValueError:
            return None
    try:
        value = int(usec)
    except ValueError:
        return None
    if value <= 0:
        return None
    return value / 2e6


class SdNotifier:
    """Sends notifications to the service manager; never raises, never blocks."""

    def __init__(self, address: str | None = None, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        self._address = socket_address(address if address is not None else env.get("NOTIFY_SOCKET"))
        self._sock: socket.socket | None = None
        self.watchdog_interval_s = watchdog_interval_s(env)
        self.sent: int = 0
        self.failed: int = 0
        self._warned = False

    @property
    def enabled(self) -> bool:
        return self._address is not None

    def notify(self, *assignments: str) -> bool:
        """Send `KEY=value` lines as one datagram. True if it was sent."""
        if self._address is None or not assignments:
            return False
        payload = "\n".join(a.replace("\n", " ") for a in assignments).encode("utf-8", "replace")
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
                self._sock.setblocking(False)
            self._sock.sendto(payload, self._address)
        except OSError as exc:
            self.failed += 1
            if not self._warned:
                self._warned = True
                log.warning("sd_notify to %s failed: %s", os.environ.get("NOTIFY_SOCKET", "?"), exc)
            return False
        self.sent += 1
        return True

    # The messages frictiond uses ------------------------------------------------------------
    def ready(self, status: str | None = None) -> bool:
        lines = ["READY=1"] + ([f"STATUS={status}"] if status else [])
        return self.notify(*lines)

    def status(self, text: str) -> bool:
        return self.notify(f"STATUS={text}")

    def watchdog(self) -> bool:
        return self.notify("WATCHDOG=1")

    def reloading(self) -> bool:
        usec = time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000
        return self.notify("RELOADING=1", f"MONOTONIC_USEC={usec}")

    def stopping(self, status: str | None = None) -> bool:
        lines = ["STOPPING=1"] + ([f"STATUS={status}"] if status else [])
        return self.notify(*lines)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> "SdNotifier":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
