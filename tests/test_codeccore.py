"""The compiled codec (`frictiond._codeccore`) against its Python twins: input decoding
(`InputCodec.decode`), output packing (`_Packer`, and cantools' own encoder) and `e2e.protect`."""
from __future__ import annotations

import math

import cantools
import numpy as np
import pytest

from frictiond import codec as codec_module
from frictiond.codec import DecodeFailure, InputCodec, OutputCodec, _limits, _Packer, load_databases
from frictiond.config import default_config_path, load_config
from frictiond.e2e import protect
from frictiond.frames import Frame
from frictiond.samples import FrictionEstimate, PhysicalSample, Status

from .conftest import REPO, assert_each_refused, edited_dbc

core = codec_module.compiled_codec
needs_core = pytest.mark.skipif(core is None, reason="not built (test_the_compiled_codec_is_built fails instead)")

# Layouts an outside DBC may use for its own messages: both byte orders, signed fields, negative
# and fractional scales, offsets, a 1-bit flag, a 52-bit field, a multiplexed message (a table
# per page), signals with value names, a float signal and a 12-byte FD payload (cantools' path).
DBC = """VERSION ""
BS_:
BU_: GW
BO_ 256 LITTLE: 8 GW
 SG_ A : 0|12@1+ (0.01,-5) [-5|35.95] "" GW
 SG_ B : 12|10@1- (0.5,0) [0|0] "" GW
 SG_ C : 22|1@1+ (1,0) [0|1] "" GW
 SG_ D : 23|16@1- (-0.25,3) [0|0] "" GW
 SG_ E : 39|25@1+ (1,0) [0|0] "" GW
BO_ 257 BIG: 8 GW
 SG_ P : 7|12@0+ (0.001,0) [0|4] "" GW
 SG_ Q : 11|9@0- (2,-10) [0|0] "" GW
 SG_ R : 18|3@0+ (1,0) [0|7] "" GW
 SG_ S : 31|16@0- (0.1,0) [-100|100] "" GW
 SG_ T : 56|8@1+ (1,0) [0|0] "" GW
BO_ 258 MIXED: 7 GW
 SG_ U : 0|8@1+ (1,0) [0|0] "" GW
 SG_ V : 15|20@0+ (0.0001,-50) [0|0] "" GW
 SG_ W : 40|4@1- (1,0) [0|0] "" GW
BO_ 259 WIDE: 8 GW
 SG_ X : 0|52@1+ (1,0) [0|0] "" GW
 SG_ Y : 52|12@1- (1,0) [0|0] "" GW
BO_ 260 MUXED: 8 GW
 SG_ Page M : 0|4@1+ (1,0) [0|3] "" GW
 SG_ One m1 : 8|16@1+ (0.1,0) [0|0] "" GW
 SG_ Two m2 : 8|8@1- (1,0) [0|0] "" GW
BO_ 261 FLOATY: 8 GW
 SG_ F : 0|32@1- (1,0) [0|0] "" GW
 SG_ G : 32|16@1+ (1,0) [0|0] "" GW
BO_ 262 FD: 12 GW
 SG_ H : 0|16@1+ (0.5,0) [0|0] "" GW
 SG_ I : 80|16@1+ (1,0) [0|0] "" GW
SIG_VALTYPE_ 261 F : 1;
VAL_ 257 R 0 "off" 7 "full" ;
VAL_ 260 Page 1 "first" 2 "second" ;
"""


def test_the_compiled_codec_is_built():
    assert core is not None, "frictiond._codeccore did not build: see the pip install output (gcc, python3-dev)"


@pytest.fixture(scope="module")
def messages():
    return cantools.database.load_string(DBC, "dbc", strict=False).messages


def _packer(message) -> _Packer:
    return _Packer(message, {sig.name: _limits(sig) for sig in message.signals})


def _values(rng: np.random.Generator, message, packer: _Packer) -> dict:
    """Values across each signal's range and beyond it, with NaN, ±inf, ints and bools."""
    values = {}
    for sig in message.signals:
        lo, hi = packer.limits[sig.name]
        kind = rng.integers(10)
        if kind == 0:
            value = float(rng.choice([math.nan, math.inf, -math.inf]))
        elif kind == 1:
            value = int(rng.integers(-3, 4)) if rng.integers(2) else bool(rng.integers(2))
        elif kind == 2:
            value = float(rng.uniform(lo - abs(hi - lo), hi + abs(hi - lo)))   # clipped
        elif kind == 3 and sig.scale:
            value = float((round(rng.uniform(lo, hi) / sig.scale) + 0.5) * sig.scale)   # a rounding tie
        else:
            value = float(rng.uniform(lo, hi))
        values[sig.name] = value
    if message.name == "MUXED":
        values["Page"] = int(rng.integers(1, 3))
    return values


@needs_core
def test_pack_is_bit_for_bit_the_python_packer_and_cantools(messages):
    rng = np.random.default_rng(11)
    compiled_counts = {}
    for message in messages:
        packer = _packer(message)
        compiled_counts[message.name] = 0
        for _ in range(400):
            values = _values(rng, message, packer)
            expected = packer.encode(values)   # the Python packer
            spec = packer.spec_for(values)
            packed = core.pack(*spec, values, packer.length) if spec is not None else None
            if packed is not None:
                compiled_counts[message.name] += 1
                assert packed == expected, (message.name, values)
                # packed and protected in one call: the same bytes as the two steps
                assert core.encode_frame(*spec, values, packer.length, message.frame_id, 5, 12) == bytes(
                    protect(message.frame_id, bytearray(expected), 5, 12))
            clipped = {name: codec_module._clamp(v, *packer.limits[name]) for name, v in values.items()}
            assert expected == bytes(message.encode(clipped, scaling=True, strict=False, padding=False)), values
    # The compiled path took the plain layouts nearly always, never the ones it must leave alone.
    for name in ("LITTLE", "BIG", "MIXED", "WIDE", "MUXED"):
        assert compiled_counts[name] > 350, compiled_counts
    for name in ("FLOATY", "FD"):
        assert compiled_counts[name] == 0, compiled_counts


@needs_core
def test_pack_refuses_what_it_cannot_encode_and_names_a_missing_signal(messages):
    packer = _packer(next(m for m in messages if m.name == "LITTLE"))
    spec, names = packer._specs[id(packer.root[0])]
    values = {"A": 1.0, "B": 2.0, "C": 1, "D": 0.5, "E": 7}
    assert core.pack(spec, names, values, 8) is not None
    assert core.pack(spec, names, {**values, "E": "seven"}, 8) is None    # not a number
    assert core.pack(spec, names, {**values, "E": 1 << 60}, 8) is None   # an int a double rounds
    with pytest.raises(KeyError, match="'D'"):
        core.pack(spec, names, {k: v for k, v in values.items() if k != "D"}, 8)
    with pytest.raises(ValueError):
        core.pack(spec[:-1], names, values, 8)
    with pytest.raises(ValueError):
        core.pack(spec, names, values, 9)


@needs_core
def test_protect_is_e2e_protect():
    rng = np.random.default_rng(12)
    for _ in range(2000):
        n = int(rng.integers(1, 13))
        payload = bytes(rng.integers(0, 256, n, dtype=np.uint8))
        data_id = int(rng.integers(0, 0x800))
        counter = int(rng.integers(0, 40))
        counter_bit = 8 * int(rng.integers(0, n)) + int(rng.integers(0, 5))   # a nibble within a byte
        assert core.protect(data_id, payload, counter, counter_bit) == bytes(
            protect(data_id, bytearray(payload), counter, counter_bit))
    with pytest.raises(IndexError):
        core.protect(0x3E0, b"\x00\x00", 1, 16)
    with pytest.raises(ValueError):   # (as protect: the nibble would cross into the next byte)
        core.protect(0x3E0, b"\x00\x00", 1, 13)


@needs_core
@pytest.mark.parametrize("wheel_spare", [False, True])
def test_output_frames_are_the_same_on_both_paths(tmp_path, wheel_spare):
    dbc = load_config(default_config_path()).can.output_dbc
    if wheel_spare:   # (a vehicle's FRICTION_WHEEL with a signal beyond the contract's: sent idle)
        dbc = edited_dbc(tmp_path, (
            ' SG_ NormalForce m0 : 52|12@1+ (5,0) [0|20475] "N" VEHICLE\n',
            ' SG_ NormalForce m0 : 52|10@1+ (20,0) [0|20460] "N" VEHICLE\n SG_ Spare : 62|2@1+ (1,1) [1|3] "" VEHICLE\n'))
    compiled = OutputCodec(load_databases([dbc]))
    floats = OutputCodec(load_databases([dbc]))
    floats.core = None
    assert None not in compiled._wheel_specs   # (the wheels' compiled call is the one under test)
    rng = np.random.default_rng(13)

    def quad(low, high):   # four numbers, now and then one not finite (sent as 0)
        values = rng.uniform(low, high, 4)
        if rng.random() < 0.2:
            values[int(rng.integers(4))] = rng.choice([math.nan, math.inf, -math.inf])
        return tuple(float(v) for v in values)

    for k in range(300):
        mu = float(rng.choice([rng.uniform(-0.5, 2.5), math.nan]))
        estimate = FrictionEstimate(0.01 * k, Status(int(rng.integers(0, 6))), mu, float(rng.uniform(0, 0.3)),
                                    float(rng.uniform(0.5, 2)), float(rng.uniform(0, 1)),
                                    quad(0, 1.5) if k % 2 else list(quad(0, 1.5)), 0.05)
        sample = PhysicalSample(0.01 * k, float(rng.uniform(0, 40)), quad(-0.2, 1.2), quad(-1, 1.5),
                                quad(0, 9000), quad(0, 9000), (True,) * 4)
        assert compiled.encode_estimate(estimate) == floats.encode_estimate(estimate)
        assert compiled.encode_wheels(estimate, sample) == floats.encode_wheels(estimate, sample)
        assert compiled._counters == floats._counters
    # encode_wheels converts its arguments by hand (METH_FASTCALL): each wrong one is refused.
    good = [compiled._wheel_specs, compiled.wheel_message.length, compiled.wheel_id, 3,
            compiled._counter_bit[compiled.wheel_id], (0.1,) * 4, (0.5,) * 4, (0.9,) * 4, (3000.0,) * 4,
            compiled._extra_values[compiled.wheel_id]]
    assert len(core.encode_wheels(*good)) == 4
    assert_each_refused(core.encode_wheels, good,
                        ((0, list(good[0])), (1, 8.0), (2, "id"), (3, 1.5), (4, None), (9, [])))


def _decode_both(compiled, floats, frame):
    """Both paths' verdicts on a frame: (values, message) or the DecodeFailure's text."""
    out = []
    for codec in (compiled, floats):
        try:
            decoded = codec.decode(frame)
            out.append(None if decoded is None else (decoded.message, decoded.is_trigger, decoded.values))
        except DecodeFailure as exc:
            out.append(("failure", exc.reason, str(exc)))
    return out


@needs_core
@pytest.mark.parametrize("config_path, marks_invalid_codes", [
    (default_config_path(), False),   # (its ranges span each field: nothing to refuse)
    (REPO / "config" / "examples" / "saloon_x.yaml", True),
    (REPO / "config" / "examples" / "saloon_x_master_cylinder.yaml", True),
])
def test_decode_is_the_same_on_both_paths(config_path, marks_invalid_codes):
    config = load_config(config_path)
    db = load_databases(config.can.dbc, strict=config.can.dbc_strict)
    compiled = InputCodec(db, config.signals, config.vehicle.wheel_radius)
    floats = InputCodec(db, config.signals, config.vehicle.wheel_radius)
    floats.core = None
    plans = list(compiled._plans.values())
    assert any(plan.compiled is not None for plan in plans)
    rng = np.random.default_rng(14)
    verdicts = {"ok": 0, "failure": 0}
    for k in range(6000):
        plan = plans[k % len(plans)]
        kind = rng.integers(4)
        if kind == 0:   # random bits: out-of-range codes and all
            data = bytes(rng.integers(0, 256, plan.length, dtype=np.uint8))
        elif kind == 1:  # all ones: the usual "invalid" code
            data = b"\xff" * plan.length
        else:           # a plausible frame: the simulator's encoder on random values in range
            values = {s.name: float(rng.uniform(0, 30)) for s in plan.signals}
            data = compiled.encode_input(plan.name, values)[0]
        a, b = _decode_both(compiled, floats, Frame(0.01 * k, plan.frame_id, data))
        assert a == b, (plan.name, data.hex())
        verdicts["failure" if a[0] == "failure" else "ok"] += 1
    assert verdicts["ok"] > 2000, verdicts
    assert (verdicts["failure"] > 500) == marks_invalid_codes, verdicts
    assert compiled.counter_jumps == floats.counter_jumps


@needs_core
def test_unpack_si_refuses_tables_that_do_not_agree():
    config = load_config(default_config_path())
    codec = InputCodec(load_databases(config.can.dbc), config.signals, config.vehicle.wheel_radius)
    fields, checks, si, names, counter = next(p.compiled for p in codec._plans.values() if p.compiled)
    with pytest.raises(ValueError):
        core.unpack_si(fields, checks, si, names[:-1], counter, b"\x00" * 8)
    with pytest.raises(ValueError):
        core.unpack_si(fields, checks, si, names, counter, b"\x00" * 9)
    # Its arguments are converted by hand (METH_FASTCALL): wrong ones are refused, none crashes.
    good = [fields, checks, si, names, counter, b"\x00" * 8]
    assert_each_refused(core.unpack_si, good,
                        ((0, "text"), (1, None), (2, 3), (3, list(names)), (4, 1.0), (4, "1"), (5, [0] * 8)))
    assert core.unpack_si(*good) is not None
    assert core.unpack_si(bytearray(fields), memoryview(checks), si, names, counter, bytearray(8)) == core.unpack_si(*good)


@needs_core
def test_a_multiplexed_estimate_message_is_packed_page_by_page(tmp_path):
    # A vehicle's output DBC may put signals of FRICTION_ESTIMATE on pages of a multiplexer:
    # each frame must be packed by the page its own values select.
    path = edited_dbc(tmp_path, (" SG_ EstimatorStatus : 12|4@1+", " SG_ EstimatorStatus M : 12|4@1+"),
                      (" SG_ Confidence : 54|8@1+", " SG_ Confidence m3 : 54|8@1+"))
    compiled, floats = OutputCodec(load_databases([path])), OutputCodec(load_databases([path]))
    floats.core = None
    for status in Status:
        estimate = FrictionEstimate(0.0, status, 0.8, 0.1, 1.0, 0.9)
        data = compiled.encode_estimate(estimate)
        assert data == floats.encode_estimate(estimate), status
        decoded = compiled.decode_output(Frame(0.0, compiled.estimate_id, data))
        assert decoded["e2e"] == "ok" and ("Confidence" in decoded) == (status == Status.VALID)
