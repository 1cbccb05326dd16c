"""The SocketCAN receive path's frame times: on candump's microsecond grid, so that a candump
recording of the bus replays exactly what the daemon computed live."""
from __future__ import annotations

import socket
import struct
import time
from types import SimpleNamespace

import can
import pytest
from can.interfaces.socketcan import constants
from can.interfaces.socketcan.socketcan import build_can_frame

from frictiond.busio import SocketcanDirect, message_to_frame


class _OneFrameSocket:
    """A socket whose one queued frame carries the given kernel receive time (s, ns)."""

    def __init__(self, seconds: int, nanoseconds: int) -> None:
        self.stamp = struct.pack("@ll", seconds, nanoseconds)

    def setblocking(self, flag: bool) -> None:
        pass

    def recvmsg(self, bufsize: int, ancbufsize: int) -> tuple:
        frame = build_can_frame(can.Message(arbitration_id=0xB0, data=b"\x01\x02", is_extended_id=False))
        return frame, [(socket.SOL_SOCKET, constants.SO_TIMESTAMPNS, self.stamp)], 0, ("vcan0",)


@pytest.mark.parametrize("nanoseconds", [862_652_000, 862_652_999, 862_652_500, 0, 999_999_999])
def test_receive_time_is_the_kernel_time_truncated_to_the_microsecond_as_candump_prints_it(nanoseconds):
    seconds = 1_795_886_605
    direct = SocketcanDirect(SimpleNamespace(channel="vcan0"), _OneFrameSocket(seconds, nanoseconds))
    frame = message_to_frame(direct.recv(0.0))
    # the float candump's text "(1795886605.862652)" reads as
    assert frame.time_s == float(f"{seconds}.{nanoseconds // 1000:06d}")
    assert frame.can_id == 0xB0 and frame.data == b"\x01\x02"


def test_a_real_socket_timestamp_lands_on_the_microsecond_grid():
    # A UDP socket carries the same SO_TIMESTAMPNS ancillary data a CAN_RAW socket does; its payload
    # here is a CAN frame, so python-can's own parser reads it.
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        receiver.bind(("127.0.0.1", 0))
        receiver.setsockopt(socket.SOL_SOCKET, constants.SO_TIMESTAMPNS, 1)
        direct = SocketcanDirect(SimpleNamespace(channel="lo"), receiver)
        times = []
        for i in range(20):
            sender.sendto(build_can_frame(can.Message(arbitration_id=0x100 + i, data=bytes([i]))),
                          receiver.getsockname())
            msg = direct.recv(1.0)
            assert msg is not None and msg.arbitration_id == 0x100 + i
            times.append(msg.timestamp)
        # (python-can's seconds + ns·1e-9 is off this grid for all but ~1 in 1000 frames)
        assert all(t == float(f"{t:.6f}") for t in times), times
        assert all(abs(t - time.time()) < 5.0 for t in times)
        assert times == sorted(times)
        assert direct.recv(0.0) is None          # nothing queued: None, not an error
    finally:
        receiver.close()
        sender.close()


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_can_fd_frames_keep_their_bytes_through_a_log_file(tmp_path, suffix):
    from frictiond.busio import LogWriter, read_log
    from frictiond.frames import Frame

    frames = [Frame(1.0, 0xB0, bytes(range(16))), Frame(1.01, 0xC0, bytes(6)), Frame(1.02, 0xB0, bytes(range(1, 17)))]
    path = tmp_path / f"fd{suffix}"
    with LogWriter(path) as writer:
        writer.write_all(frames)
    back = list(read_log(path))
    assert [(f.can_id, f.data) for f in back] == [(f.can_id, f.data) for f in frames]


def test_a_socketcan_bus_is_opened_for_fd_when_inputs_are_fd(monkeypatch):
    from frictiond import busio

    seen = {}

    def fake_bus(**kwargs):
        seen.update(kwargs)
        return SimpleNamespace(socket=None)

    monkeypatch.setattr(busio.can, "Bus", fake_bus)
    busio.open_bus("socketcan", "vcan0", [0xB0], fd=True)
    assert seen["fd"] is True and seen["can_filters"] == [{"can_id": 0xB0, "can_mask": 0x7FF, "extended": False}]
    seen.clear()
    busio.open_bus("socketcan", "vcan0", [0xB0])
    assert "fd" not in seen
    seen.clear()
    busio.open_bus("virtual", "x", [0xB0], fd=True)   # (its FD settings are its own)
    assert "fd" not in seen


def test_29_bit_inputs_get_29_bit_kernel_filters(monkeypatch):
    from frictiond import busio

    seen = {}
    monkeypatch.setattr(busio.can, "Bus", lambda **kwargs: seen.update(kwargs) or SimpleNamespace(socket=None))
    busio.open_bus("socketcan", "vcan0", [0xB0, 0xC0], extended_ids=[0xC0])
    assert seen["can_filters"] == [{"can_id": 0xB0, "can_mask": 0x7FF, "extended": False},
                                   {"can_id": 0xC0, "can_mask": 0x7FF, "extended": False},
                                   {"can_id": 0xC0, "can_mask": 0x1FFFFFFF, "extended": True}]
