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
    "(16.000000) vcan0 80000123#11",               # flag bits above the 29-bit ID (masked off)
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


# ---- reading only some IDs: LogFrames(keep_ids) -------------------------------------------------
KEEP = frozenset({0x0C0, 0x123, 0x7FF})


def _mixed_log(tmp_path, seed: int, first: str, last: str):
    """python-can's own candump lines of random IDs (some kept), the edge lines spread among them,
    and chosen first and last lines (the span must come from them, skipped or not)."""
    rng = np.random.default_rng(seed)
    path = tmp_path / f"mixed{seed}.log"
    with can.Logger(str(path)) as writer:
        for k in range(2000):
            extended = bool(rng.integers(6) == 0)
            can_id = int(rng.choice(sorted(KEEP))) if rng.integers(3) == 0 else int(rng.integers(0, 1 << 11))
            writer.on_message_received(can.Message(
                timestamp=100.0 + 0.001 * k, arbitration_id=can_id, is_extended_id=extended,
                data=bytes(rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8)), channel="vcan0"))
    lines = path.read_text().splitlines()
    for k, edge in enumerate(EDGE_LINES + ["", "   ", "\t"]):
        lines.insert(90 * k + 3, edge)
    path.write_text("\n".join([first] + lines + [last]) + "\n")
    return path


def _expected(path):
    every = [message_to_frame(m) for m in can.LogReader(str(path))]
    kept = [f for f in every if f.is_extended or f.is_error or f.is_remote or f.can_id in KEEP]
    return every, kept


@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("block_chars", [1 << 20, 4096, 37])
@pytest.mark.parametrize("ends", [("(0.500000) vcan0 456#11", "(999.000000) vcan0 001#22"),   # skipped
                                  ("(0.500000) vcan0 0C0#11", "(999.000000) vcan0 7FF#22"),   # kept
                                  ("(0.500000) vcan0 456#R", "(999.000000)  vcan0  456#22")])  # Python path
def test_kept_ids_are_the_frames_python_can_reads_less_the_unrelated(tmp_path, monkeypatch, compiled, block_chars, ends):
    if compiled and core is None:
        pytest.fail("frictiond._logcore is not built")
    path = _mixed_log(tmp_path, 5, *ends)
    every, kept = _expected(path)
    if not compiled:
        monkeypatch.setattr(busio, "compiled_log", None)
    monkeypatch.setattr(busio, "_BLOCK_CHARS", block_chars)   # lines split across blocks
    frames = busio.LogFrames(path, keep_ids=KEEP)
    assert list(frames) == kept
    assert frames.skipped == len(every) - len(kept) > 1000
    assert (frames.first_time_s, frames.last_time_s) == (every[0].time_s, every[-1].time_s)
    assert list(busio.LogFrames(path)) == every   # no keep_ids: everything, still in blocks
    assert list(frames) == kept and frames.skipped == len(every) - len(kept)   # a second pass starts afresh


def test_kept_ids_in_other_formats_follow_the_same_rule(tmp_path):
    source = _mixed_log(tmp_path, 6, "(0.500000) vcan0 456#11", "(999.000000) vcan0 0C0#22")
    path = tmp_path / "mixed.asc"
    with can.Logger(str(path)) as writer:
        for msg in can.LogReader(str(source)):
            if not msg.is_fd:
                writer.on_message_received(msg)
    every = [message_to_frame(m) for m in can.LogReader(str(path))]
    frames = busio.LogFrames(path, keep_ids=KEEP)
    kept = list(frames)
    assert kept == [f for f in every if f.is_extended or f.is_error or f.is_remote or f.can_id in KEEP]
    assert frames.skipped == len(every) - len(kept) > 1000
    assert (frames.first_time_s, frames.last_time_s) == (every[0].time_s, every[-1].time_s)


def test_a_block_beyond_latin1_takes_the_python_path(tmp_path):
    path = tmp_path / "wide.log"
    path.write_text("(1.000000) vcan0 0C0#01\n(2.000000) vcän€ 456#02\n(3.000000) vcan0 456#03\n", encoding="utf-8")
    frames = busio.LogFrames(path, keep_ids=KEEP)
    if core is not None:
        assert core.candump_lines(path.read_text(encoding="utf-8"), Frame, busio._id_bitmap(KEEP)) is None
    import locale
    if locale.getpreferredencoding(False).lower().replace("-", "") != "utf8":
        pytest.skip("the log is read in the locale's encoding, which is not UTF-8 here")
    assert [f.can_id for f in frames] == [0x0C0]
    assert frames.skipped == 2 and frames.last_time_s == 3.0


@needs_core
def test_compiled_candump_lines_match_the_python_reference():
    rng = np.random.default_rng(8)
    pool = EDGE_LINES + ["", "  ", "(1.000000) vcan0 0C0#0102", "(2.000000) vcan0 456#0102", "(2.5) vcan0 FFF#",
                         "(3.000000) vcan0 00000456#01", "(4.0) can0 7FF#ABCDEF", "(5.0) vcan0 123#1"]
    keep_bits = busio._id_bitmap(KEEP)
    for trial in range(400):
        lines = [pool[int(i)] for i in rng.integers(0, len(pool), int(rng.integers(0, 12)))]
        text = "\n".join(lines) + ("\n" if rng.integers(2) else "")
        for keep, bits in ((KEEP, keep_bits), (None, None)):
            got = core.candump_lines(text, Frame, bits)
            want = busio._candump_lines(text, keep)
            assert got[:3] == want[:3], (text, keep)
            assert np.array_equal(got[3:], want[3:], equal_nan=True), (text, keep)
            assert all(type(item) in (Frame, str) for item in got[0])
    with pytest.raises(TypeError):
        core.candump_lines("(1.0) vcan0 123#11\n", Frame, b"\x00" * 10)
    with pytest.raises(TypeError):
        core.candump_lines("(1.0) vcan0 123#11\n", dict, None)
