"""Reading candump logs: the compiled line parser (`frictiond._logcore`), the regular-expression
path it replaces and python-can's own reader give the same frames."""
from __future__ import annotations

import can
import numpy as np
import pytest

from frictiond import busio
from frictiond.busio import message_to_frame, read_log
from frictiond.frames import Frame

core = busio.compiled_log
needs_core = pytest.mark.skipif(core is None, reason="not built (test_the_compiled_log_reader_is_built fails instead)")

# Lines python-can's reader takes that are not the common case, and common ones at its edges.
EDGE_LINES = [
    "(0.000000) vcan0 123#",                       # no data
    "(1.5) can1 7FF#0011223344556677",             # short time, highest standard ID
    "(-2.250000) vcan0 001#AB",                    # negative time
    "(3.000001) vcan0 1#aabbcc",                   # one-digit ID, lower-case hex
    "(4.000000) vcan0 00000123#11",                # an extended ID that is small
    "(5.000000) vcan0 1FFFFFFF#DEADBEEF",          # the highest extended ID
    "(6.000000) vcan0 123#1122 R",                 # newer can-utils' direction suffix
    "(6.500000) vcan0 123#1122 T",
    "(7.000000) vcan0 123#R",                      # remote frames
    "(7.500000) vcan0 123#R4",
    "(8.000000) vcan0 123##1112233",               # CAN FD with flags
    "(9.000000) vcan0 20000080#0000000000000000",  # an error frame (bus error class)
    "(10.000000) vcan0 20000004#0000000000000000",  # error flag set, other class
    "(11.000000)  vcan0  123#11",                  # two spaces: python-can splits on any run
    "(12.000000) vcan0 123#11\r",                  # a CR from a DOS copy
    "(13." + "1" * 80 + ") vcan0 123#11",          # a time longer than the parser's buffer
    "(14.000000) 0 123#11",                        # a numeric channel
    "(15.000000) vcan0 123#" + "11" * 64,          # 64 data bytes (FD length without the FD marker)
]


def _write(tmp_path, lines):
    path = tmp_path / "edge.log"
    path.write_text("\n".join(lines) + "\n", encoding="ascii")
    return path


def test_the_compiled_log_reader_is_built():
    assert core is not None, "frictiond._logcore did not build: see the pip install output (gcc, python3-dev)"


@needs_core
def test_compiled_regex_and_python_can_read_the_same_frames(tmp_path, monkeypatch):
    rng = np.random.default_rng(31)
    path = tmp_path / "drive.log"
    with can.Logger(str(path)) as writer:   # python-can's candump writer: the real format
        for k in range(3000):
            extended = bool(rng.integers(4) == 0)
            writer.on_message_received(can.Message(
                timestamp=1700000000.0 + 0.001 * k + float(rng.uniform(0, 1e-3)),
                arbitration_id=int(rng.integers(0, 1 << 29 if extended else 1 << 11)), is_extended_id=extended,
                data=bytes(rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8)), channel="vcan0"))
    text = path.read_text()
    lines = text.splitlines()
    for k, edge in enumerate(EDGE_LINES):   # spread among the ordinary lines
        lines.insert(100 * k + 7, edge)
    path.write_text("\n".join(lines) + "\n")

    compiled = list(read_log(path))
    monkeypatch.setattr(busio, "compiled_log", None)
    regex = list(read_log(path))
    reference = [message_to_frame(m) for m in can.LogReader(str(path))]
    assert len(compiled) == len(reference) == 3000 + len(EDGE_LINES)
    assert regex == reference
    assert compiled == reference
    assert all(type(f) is Frame for f in compiled)


@needs_core
def test_candump_frame_takes_only_the_common_line():
    parse = core.candump_frame
    assert parse("(1.250000) vcan0 0C0#0102\n", Frame) == Frame(1.25, 0xC0, b"\x01\x02")
    assert parse("(1.250000) vcan0 00000C0#0102\n", Frame) == Frame(1.25, 0xC0, b"\x01\x02", True)
    for other in ("(1.25) vcan0 123#R", "(1.25) vcan0 123##0AA", "(1.25) vcan0 20000080#00", "(1.25) vcan0 123#1",
                  "(1.25) vcan0 123#11 X", "(1.25) vcan0 123456789#11", "(1.25)vcan0 123#11", "(1.25) vcän0 123#11",
                  "(1.) vcan0 123#11", "(.5) vcan0 123#11", "", "\n", "garbage"):
        assert parse(other, Frame) is None, other
    with pytest.raises(TypeError):
        parse(b"(1.0) vcan0 123#11", Frame)
