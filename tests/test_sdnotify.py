"""sd_notify messages, received on a real AF_UNIX datagram socket."""
from __future__ import annotations

import os
import socket
import uuid

import pytest

from frictiond.sdnotify import SdNotifier, socket_address, watchdog_interval_s


def _receiver(address):
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(address)
    sock.settimeout(2.0)
    return sock


@pytest.fixture
def path_socket(tmp_path):
    path = str(tmp_path / "notify")
    sock = _receiver(path)
    yield path, sock
    sock.close()


def test_messages_arrive_as_single_datagrams(path_socket):
    path, sock = path_socket
    n = SdNotifier(environ={"NOTIFY_SOCKET": path})
    assert n.enabled
    assert n.ready("INIT MuMax -")
    assert sock.recv(4096) == b"READY=1\nSTATUS=INIT MuMax -"
    assert n.status("VALID MuMax 0.950, 400 frames/s")
    assert sock.recv(4096) == b"STATUS=VALID MuMax 0.950, 400 frames/s"
    assert n.watchdog()
    assert sock.recv(4096) == b"WATCHDOG=1"
    assert n.reloading()
    lines = sock.recv(4096).decode().split("\n")
    assert lines[0] == "RELOADING=1" and lines[1].startswith("MONOTONIC_USEC=") and int(lines[1].split("=")[1]) > 0
    assert n.stopping()
    assert sock.recv(4096) == b"STOPPING=1"
    assert n.sent == 5 and n.failed == 0
    n.close()


def test_newlines_in_a_status_cannot_inject_assignments(path_socket):
    path, sock = path_socket
    n = SdNotifier(environ={"NOTIFY_SOCKET": path})
    n.status("bad\nREADY=1")
    assert sock.recv(4096) == b"STATUS=bad READY=1"


def test_abstract_namespace_address():
    name = f"frictiond-test-{uuid.uuid4().hex}"
    sock = _receiver("\0" + name)
    try:
        n = SdNotifier(environ={"NOTIFY_SOCKET": "@" + name})
        assert n.ready()
        assert sock.recv(4096) == b"READY=1"
    finally:
        sock.close()


def test_without_notify_socket_everything_is_a_no_op():
    n = SdNotifier(environ={})
    assert not n.enabled
    assert not n.ready() and not n.watchdog() and not n.stopping()
    assert n.watchdog_interval_s is None


def test_missing_socket_is_counted_not_raised(tmp_path, caplog):
    n = SdNotifier(environ={"NOTIFY_SOCKET": str(tmp_path / "absent")})
    assert not n.ready()
    assert not n.watchdog()
    assert n.failed == 2
    assert sum("sd_notify" in r.message for r in caplog.records) == 1   # warned once


def test_address_forms():
    assert socket_address("/run/systemd/notify") == "/run/systemd/notify"
    assert socket_address("@abc") == b"\0abc"
    assert socket_address("") is None and socket_address(None) is None
    assert socket_address("vsock:2:1234") is None


def test_watchdog_interval_is_half_of_watchdog_usec():
    assert watchdog_interval_s({"WATCHDOG_USEC": "20000000"}) == 10.0
    assert watchdog_interval_s({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": str(os.getpid())}) == 10.0
    assert watchdog_interval_s({"WATCHDOG_USEC": "20000000", "WATCHDOG_PID": "1"}, pid=2) is None
    assert watchdog_interval_s({"WATCHDOG_USEC": "0"}) is None
    assert watchdog_interval_s({"WATCHDOG_USEC": "x"}) is None
    assert watchdog_interval_s({}) is None
    n = SdNotifier(environ={"NOTIFY_SOCKET": "@x", "WATCHDOG_USEC": "3000000"})
    assert n.watchdog_interval_s == 1.5
