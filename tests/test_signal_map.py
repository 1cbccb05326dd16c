"""The signal map against small vehicle DBCs written here: units, byte orders, scales, pressures,
rates, multiplexing, optional inputs, lenient and split DBCs (issue 6, "bring your own car")."""
from __future__ import annotations

import math
import subprocess
import sys

import cantools
import pytest
import yaml

from frictiond.codec import InputCodec, load_databases, validate_against_dbc
from frictiond.config import ConfigError, load_config
from frictiond.evaluation import evaluate
from frictiond.frames import Frame
from frictiond.replay import estimates_of
from frictiond.samples import Status
from frictiond.sim_frames import simulate_frames

from .conftest import REPO

HEAD = 'VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: ESC ECU\n\n'
RADIUS = 0.31  # wheel radius of the default vehicle
CYCLE_DEF = 'BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;\nBA_DEF_DEF_ "GenMsgCycleTime" 0;\n'

# Pieces every DBC below shares unless a test replaces them.
ACCEL = """BO_ 300 ACC: 8 ESC
 SG_ LongAcc : 7|16@0- (0.001,0) [-30|30] "m/s^2" ECU
 SG_ LatAcc : 23|16@0- (0.001,0) [-30|30] "m/s^2" ECU
 SG_ Yaw : 39|16@0- (0.0001,0) [-3|3] "rad/s" ECU
"""
PRESS = """BO_ 400 PRESS: 8 ESC
 SG_ P_FL : 7|16@0+ (0.01,0) [0|600] "bar" ECU
 SG_ P_FR : 23|16@0+ (0.01,0) [0|600] "bar" ECU
 SG_ P_RL : 39|16@0+ (0.01,0) [0|600] "bar" ECU
 SG_ P_RR : 55|16@0+ (0.01,0) [0|600] "bar" ECU
"""


def wheels_msg(unit: str = "rad/s", scale: float = 0.01, bits: int = 16, order: str = "0", offset: float = 0.0,
               frame_id: int = 200, name: str = "WHL") -> str:
    """Four wheel-speed fields of `bits` bits, big-endian ('0') or little-endian ('1')."""
    top = offset + scale * ((1 << bits) - 2)
    lines = [f"BO_ {frame_id} {name}: 8 ESC"]
    for i, w in enumerate(("FL", "FR", "RL", "RR")):
        start = 16 * i + (7 if order == "0" else 0)
        lines.append(f' SG_ V_{w} : {start}|{bits}@{order}+ ({scale:g},{offset:g}) [{offset:g}|{top:g}] "{unit}" ECU')
    return "\n".join(lines) + "\n"


def cycles(**ms: int) -> str:
    ids = {"WHL": 200, "ACC": 300, "PRESS": 400}
    return CYCLE_DEF + "".join(f'BA_ "GenMsgCycleTime" BO_ {ids.get(k, k)} {v};\n' for k, v in ms.items())


def base_signals() -> dict:
    s = {f"wheel_speed_{w}": {"message": "WHL", "signal": f"V_{w.upper()}"} for w in ("fl", "fr", "rl", "rr")}
    s.update(accel_long="ACC.LongAcc", accel_lat="ACC.LatAcc", yaw_rate="ACC.Yaw")
    s.update({f"brake_pressure_{w}": f"PRESS.P_{w.upper()}" for w in ("fl", "fr", "rl", "rr")})
    return s


def make_config(tmp_path, dbc_texts, signals, strict: bool = True, name: str = "car"):
    """Write DBC file(s) and a config using them next to each other; returns the config path."""
    data = yaml.safe_load((REPO / "config" / "frictiond.yaml").read_text())
    texts = [dbc_texts] if isinstance(dbc_texts, str) else list(dbc_texts)
    files = []
    for i, text in enumerate(texts):
        path = tmp_path / f"{name}{i}.dbc"
        path.write_text(HEAD + text)
        files.append(path.name)
    data["can"]["dbc"] = files if len(files) > 1 else files[0]
    data["can"]["dbc_strict"] = strict
    data["signals"] = signals
    data.pop("output", None)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def codec_for(path) -> InputCodec:
    config = load_config(path)
    return validate_against_dbc(config)[0]


def decode_physical(codec: InputCodec, message: str, physical: dict, t: float = 0.0) -> dict[str, float]:
    msg = codec.db.get_message_by_name(message)
    return codec.decode(Frame(t, msg.frame_id, msg.encode(physical))).values


def check_config(path):
    return subprocess.run([sys.executable, "-m", "frictiond.cli.main", "check-config", str(path)],
                          capture_output=True, text=True, timeout=60)


# ------------------------------------------------------------------------------------- units
@pytest.mark.parametrize("unit,scale,per_rad_s", [
    ("km/h", 0.01, RADIUS * 3.6),
    ("m/s", 0.005, RADIUS),
    ("rad/s", 0.01, 1.0),
    ("rpm", 0.1, 60 / (2 * math.pi)),
    ("U/min", 0.1, 60 / (2 * math.pi)),
    ("mph", 0.01, RADIUS / 0.44704),
    ("km/hr", 0.01, RADIUS * 3.6),      # spellings other DBCs use
    ("kmph", 0.01, RADIUS * 3.6),
    ("rad/sec", 0.01, 1.0),
])
def test_wheel_speed_units(tmp_path, unit, scale, per_rad_s):
    codec = codec_for(make_config(tmp_path, wheels_msg(unit, scale) + ACCEL + PRESS, base_signals()))
    omega = {"FL": 64.5, "FR": 64.0, "RL": 30.25, "RR": 0.0}
    values = decode_physical(codec, "WHL", {f"V_{w}": round(v * per_rad_s / scale) * scale for w, v in omega.items()})
    for w, v in omega.items():
        assert values[f"wheel_speed_{w.lower()}"] == pytest.approx(v, abs=scale / per_rad_s + 1e-9), unit


@pytest.mark.parametrize("accel_unit,per_mps2,pressure_unit,per_bar", [
    ("m/sec^2", 1.0, "hPa", 1000.0), ("ms^-2", 1.0, "mbar", 1000.0), ("g", 1 / 9.80665, "kPa", 100.0)])
def test_acceleration_and_pressure_spellings(tmp_path, accel_unit, per_mps2, pressure_unit, per_bar):
    text = (wheels_msg() + ACCEL.replace('"m/s^2"', f'"{accel_unit}"')
            + PRESS.replace('(0.01,0) [0|600] "bar"', f'(0.1,0) [0|6000] "{pressure_unit}"'))
    codec = codec_for(make_config(tmp_path, text, base_signals()))
    accel = decode_physical(codec, "ACC", {"LongAcc": round(-7.5 * per_mps2, 3), "LatAcc": 0.0, "Yaw": 0.0})
    assert accel["accel_long"] == pytest.approx(-7.5, abs=1e-3 / per_mps2)
    press = decode_physical(codec, "PRESS", {f"P_{w}": 42.0 * per_bar / 100.0 for w in ("FL", "FR", "RL", "RR")})
    assert press["brake_pressure_fl"] == pytest.approx(0.42, rel=1e-6)


@pytest.mark.parametrize("bits,order,offset", [(14, "0", 0.0), (15, "0", 0.0), (16, "0", -100.0), (14, "1", -50.0),
                                                (16, "1", 0.0)])
def test_field_widths_byte_orders_and_offsets_agree_with_cantools(tmp_path, bits, order, offset):
    text = wheels_msg("km/h", 0.02, bits, order, offset) + ACCEL + PRESS
    codec = codec_for(make_config(tmp_path, text, base_signals()))
    reference = cantools.database.load_string(HEAD + text).get_message_by_name("WHL")
    physical = {"V_FL": offset + 0.02 * 4000, "V_FR": offset + 0.02 * ((1 << bits) - 3), "V_RL": offset, "V_RR": offset + 1.0}
    data = reference.encode(physical)
    values = codec.decode(Frame(0.0, 200, data)).values
    for w in ("FL", "FR", "RL", "RR"):
        expected = reference.decode(data)[f"V_{w}"] / 3.6 / RADIUS
        assert values[f"wheel_speed_{w.lower()}"] == pytest.approx(expected, rel=1e-9, abs=1e-9)
    # The encoder of the simulator puts the same value back in the same bits.
    (payload,) = codec.encode_input("WHL", values)
    assert reference.decode(payload) == pytest.approx(reference.decode(data), abs=1e-9)


def test_big_endian_bits_by_hand(tmp_path):
    # 15-bit Motorola field starting at bit 3 (byte 0 bits 3..0, byte 1, byte 2 bits 7..6): raw 0x1234.
    text = """BO_ 200 WHL: 8 ESC
 SG_ V_FL : 3|15@0+ (0.01,0) [0|327.66] "km/h" ECU
 SG_ V_FR : 20|15@0+ (0.01,0) [0|327.66] "km/h" ECU
 SG_ V_RL : 37|15@0+ (0.01,0) [0|327.66] "km/h" ECU
 SG_ V_RR : 54|15@0+ (0.01,0) [0|327.66] "km/h" ECU
 SG_ Cnt_Counter : 7|4@0+ (1,0) [0|15] "" ECU
""" + ACCEL + PRESS
    codec = codec_for(make_config(tmp_path, text, base_signals()))
    raw = 0x1234
    data = bytearray(8)
    data[0] = (raw >> 11) & 0x0F
    data[1] = (raw >> 3) & 0xFF
    data[2] = (raw & 0x07) << 5
    values = codec.decode(Frame(0.0, 200, bytes(data))).values
    assert values["wheel_speed_fl"] == pytest.approx(raw * 0.01 / 3.6 / RADIUS)
    assert values["wheel_speed_fr"] == 0.0
    # 0x7FFF ("invalid") lies outside the DBC range: the frame is refused, not decoded as 327 km/h.
    data[0] |= 0x0F
    data[1] = 0xFF
    data[2] |= 0xE0
    with pytest.raises(Exception, match="out of range"):
        codec.decode(Frame(0.0, 200, bytes(data)))


def test_sign_flip_scale_g_and_deg_per_s(tmp_path):
    text = wheels_msg() + """BO_ 300 ACC: 8 ESC
 SG_ Decel : 7|16@0- (0.01,0) [-320|320] "m/s^2" ECU
 SG_ LatG : 23|12@0- (0.001,0) [-2|2] "g" ECU
 SG_ YawDeg : 27|14@0- (0.02,0) [-163.8|163.8] "deg/s" ECU
""" + PRESS
    signals = base_signals()
    signals.update(accel_long={"message": "ACC", "signal": "Decel", "scale": -1.0},
                   accel_lat="ACC.LatG", yaw_rate={"message": "ACC", "signal": "YawDeg", "scale": -1.0})
    codec = codec_for(make_config(tmp_path, text, signals))
    values = decode_physical(codec, "ACC", {"Decel": 8.5, "LatG": 0.25, "YawDeg": 10.0})
    assert values["accel_long"] == pytest.approx(-8.5)
    assert values["accel_lat"] == pytest.approx(0.25 * 9.80665)
    assert values["yaw_rate"] == pytest.approx(-math.radians(10.0))
    # A config scale on top of the DBC's (e.g. a signal in 0.1 g steps the DBC calls 1).
    signals["accel_lat"] = {"message": "ACC", "signal": "LatG", "scale": 0.5, "offset": 0.1}
    codec = codec_for(make_config(tmp_path, text, signals, name="car2"))
    values = decode_physical(codec, "ACC", {"Decel": 0.0, "LatG": 0.5, "YawDeg": 0.0})
    assert values["accel_lat"] == pytest.approx((0.5 * 0.5 + 0.1) * 9.80665)


# ----------------------------------------------------------------------------- brake pressure
BRAKE_DBC = """BO_ 400 PRESS: 8 ESC
 SG_ P_FL : 7|16@0+ (1,0) [0|60000] "kPa" ECU
 SG_ P_FR : 23|16@0+ (1,0) [0|60000] "kPa" ECU
 SG_ P_RL : 39|16@0+ (1,0) [0|60000] "kPa" ECU
 SG_ P_RR : 55|16@0+ (1,0) [0|60000] "kPa" ECU
BO_ 401 AXLE: 4 ESC
 SG_ P_Front : 0|16@1+ (0.1,0) [0|6000] "psi" ECU
 SG_ P_Rear : 16|16@1+ (0.1,0) [0|6000] "psi" ECU
BO_ 402 MC: 4 ESC
 SG_ MC_Counter : 3|4@0+ (1,0) [0|15] "" ECU
 SG_ MasterCyl : 15|12@0+ (1,0) [0|4094] "" ECU
"""


def test_brake_pressure_per_wheel_per_axle_and_master_cylinder(tmp_path):
    text = wheels_msg() + ACCEL + BRAKE_DBC
    per_wheel = base_signals()
    codec = codec_for(make_config(tmp_path, text, per_wheel, name="wheel"))
    values = decode_physical(codec, "PRESS", {"P_FL": 5000, "P_FR": 4000, "P_RL": 2500, "P_RR": 0})
    assert [values[f"brake_pressure_{w}"] for w in ("fl", "fr", "rl", "rr")] == pytest.approx([50, 40, 25, 0])

    per_axle = base_signals()
    per_axle.update({f"brake_pressure_{w}": f"AXLE.P_{'Front' if w[0] == 'f' else 'Rear'}" for w in ("fl", "fr", "rl", "rr")})
    codec = codec_for(make_config(tmp_path, text, per_axle, name="axle"))
    values = decode_physical(codec, "AXLE", {"P_Front": 1000.0, "P_Rear": 500.0})
    assert values["brake_pressure_fl"] == values["brake_pressure_fr"] == pytest.approx(68.9475729)
    assert values["brake_pressure_rl"] == values["brake_pressure_rr"] == pytest.approx(34.47378645)

    master = base_signals()
    for w, factor in (("fl", 0.1), ("fr", 0.1), ("rl", 0.07), ("rr", 0.07)):
        master[f"brake_pressure_{w}"] = {"message": "MC", "signal": "MasterCyl", "unit": "bar", "scale": factor}
    path = make_config(tmp_path, text, master, name="master")
    codec = codec_for(path)
    values = decode_physical(codec, "MC", {"MC_Counter": 0, "MasterCyl": 800})
    assert [values[f"brake_pressure_{w}"] for w in ("fl", "fr", "rl", "rr")] == pytest.approx([80, 80, 56, 56])
    # The simulator's encoder writes the shared signal once, from the first input mapped to it.
    (payload,) = codec.encode_input("MC", {"brake_pressure_fl": 40.0, "brake_pressure_fr": 41.0,
                                           "brake_pressure_rl": 40.0, "brake_pressure_rr": 40.0})
    assert codec.decode(Frame(0.0, 402, payload)).values["brake_pressure_fl"] == pytest.approx(40.0)
    out = check_config(path).stdout
    assert "MasterCyl" in out and "×0.07" in out and "×0.1" in out


def test_unitless_brake_signal(tmp_path):
    text = wheels_msg() + ACCEL + BRAKE_DBC
    signals = base_signals()
    signals.update({f"brake_pressure_{w}": "MC.MasterCyl" for w in ("fl", "fr", "rl", "rr")})
    path = make_config(tmp_path, text, signals, name="raw")
    # Without unit and scale the count is taken as bar, and check-config says so.
    proc = check_config(path)
    assert proc.returncode == 0 and "no unit in DBC; assumed bar" in proc.stdout
    signals.update({f"brake_pressure_{w}": {"message": "MC", "signal": "MasterCyl", "unit": "kPa", "scale": 10.0}
                    for w in ("fl", "fr", "rl", "rr")})
    codec = codec_for(make_config(tmp_path, text, signals, name="scaled"))
    assert decode_physical(codec, "MC", {"MC_Counter": 1, "MasterCyl": 123})["brake_pressure_rr"] == pytest.approx(12.3)
    # A unit that is not a pressure is refused, naming the input and the unit.
    signals["brake_pressure_fl"] = {"message": "MC", "signal": "MasterCyl", "unit": "km/h"}
    with pytest.raises(ConfigError, match=r"brake_pressure_fl.*'km/h' is not a pressure unit"):
        codec_for(make_config(tmp_path, text, signals, name="bad"))


# ------------------------------------------------------------------- rates, mux, optional inputs
def replay_accuracy(path, scenario="dry", seed=1):
    config = load_config(path)
    frames, sim = simulate_frames(config, scenario, seed=seed)
    pipeline, estimates = estimates_of(config, frames)
    return pipeline, frames, evaluate(estimates, sim.truth.rows())


@pytest.mark.parametrize("wheel_ms,accel_ms,press_ms", [(10, 20, 25), (20, 10, 20)])
def test_inputs_at_different_rates_update_on_the_wheel_speed_message(tmp_path, wheel_ms, accel_ms, press_ms):
    path = make_config(tmp_path, wheels_msg("km/h", 0.01) + ACCEL + PRESS
                       + cycles(WHL=wheel_ms, ACC=accel_ms, PRESS=press_ms), base_signals())
    pipeline, frames, report = replay_accuracy(path)
    wheel_frames = sum(f.can_id == 200 for f in frames)
    # One update per wheel-speed frame, none for the others.
    assert pipeline.stats.updates == wheel_frames - pipeline.front_end.skipped_triggers
    assert report.valid_count > 50 and report.false_valid_count == 0
    assert report.mae < 0.03, report.mae


MUX_DBC = """BO_ 300 ACC: 8 ESC
 SG_ Page M : 0|2@1+ (1,0) [0|3] "" ECU
 SG_ LongAcc m0 : 8|16@1- (0.001,0) [-30|30] "m/s^2" ECU
 SG_ LatAcc m0 : 24|16@1- (0.001,0) [-30|30] "m/s^2" ECU
 SG_ Yaw m1 : 8|16@1- (0.0001,0) [-3|3] "rad/s" ECU
 SG_ Other m2 : 8|16@1+ (1,0) [0|0] "" ECU
BO_ 400 PRESS: 6 ESC
 SG_ Axle M : 7|1@0+ (1,0) [0|1] "" ECU
 SG_ P_Left m0 : 15|12@0+ (0.1,0) [0|409.4] "bar" ECU
 SG_ P_Right m0 : 31|12@0+ (0.1,0) [0|409.4] "bar" ECU
 SG_ P_LeftR m1 : 15|12@0+ (0.1,0) [0|409.4] "bar" ECU
 SG_ P_RightR m1 : 31|12@0+ (0.1,0) [0|409.4] "bar" ECU
"""


def test_multiplexed_inputs(tmp_path):
    signals = base_signals()
    signals.update(brake_pressure_fl="PRESS.P_Left", brake_pressure_fr="PRESS.P_Right",
                   brake_pressure_rl="PRESS.P_LeftR", brake_pressure_rr="PRESS.P_RightR")
    path = make_config(tmp_path, wheels_msg() + MUX_DBC + cycles(WHL=10, ACC=5, PRESS=10), signals)
    codec = codec_for(path)
    # Each frame carries its page only.
    assert decode_physical(codec, "PRESS", {"Axle": 1, "P_LeftR": 12.3, "P_RightR": 4.5}) == pytest.approx(
        {"brake_pressure_rl": 12.3, "brake_pressure_rr": 4.5})
    assert set(decode_physical(codec, "ACC", {"Page": 1, "Yaw": 0.1})) == {"yaw_rate"}
    assert decode_physical(codec, "ACC", {"Page": 2, "Other": 7}) == {}
    proc = check_config(path)
    assert "P_LeftR mux [1]" in proc.stdout and "(50 Hz per page)" in proc.stdout
    pipeline, _, report = replay_accuracy(path)
    assert report.valid_count > 50 and report.false_valid_count == 0
    # Multiplexed pages cost accuracy while the front end merges pages (see test_vehicle_dbc).
    assert report.mae < 0.08, report.mae


def test_optional_inputs_absent_and_present_in_other_units(tmp_path):
    signals = base_signals()
    del signals["yaw_rate"]
    signals.update(vehicle_speed_ref=None, drive_torque_fl=None)
    path = make_config(tmp_path, wheels_msg() + ACCEL + PRESS + cycles(WHL=10, ACC=10, PRESS=10), signals)
    out = check_config(path).stdout
    for name in ("yaw_rate", "vehicle_speed_ref", "drive_torque_rr"):
        assert next(line for line in out.splitlines() if line.startswith(name)).endswith("(absent: optional)")
    _, _, report = replay_accuracy(path)
    assert report.valid_count > 50 and report.false_valid_count == 0 and report.mae < 0.03
    # A reference speed in km/h on its own message, and drive torques in kNm, resolve too.
    text = wheels_msg() + ACCEL + PRESS + """BO_ 500 REF: 8 ESC
 SG_ VRef : 7|16@0+ (0.01,0) [0|655] "km/h" ECU
 SG_ Tq_FL : 23|16@0- (0.001,0) [-30|30] "kNm" ECU
"""
    signals = base_signals() | {"vehicle_speed_ref": "REF.VRef", "drive_torque_fl": "REF.Tq_FL"}
    codec = codec_for(make_config(tmp_path, text, signals, name="ref"))
    values = decode_physical(codec, "REF", {"VRef": 72.0, "Tq_FL": -0.25})
    assert values == pytest.approx({"vehicle_speed_ref": 20.0, "drive_torque_fl": -250.0})


# --------------------------------------------------------------------- lenient and split DBCs
# The wheel message carries two signals that overlap (a status byte and a qualifier inside it):
# cantools refuses this strictly; production DBCs have it.
OVERLAPPING = wheels_msg() + """BO_ 201 WHL_STATUS: 2 ESC
 SG_ Status : 0|8@1+ (1,0) [0|255] "" ECU
 SG_ Qualifier : 4|4@1+ (1,0) [0|15] "" ECU
"""


def test_dbc_that_only_loads_leniently(tmp_path):
    strict = make_config(tmp_path, OVERLAPPING + ACCEL + PRESS, base_signals(), strict=True, name="strict")
    proc = check_config(strict)
    assert proc.returncode == 78
    (line,) = proc.stderr.strip().splitlines()
    assert "strict0.dbc" in line and "dbc_strict: false" in line
    lenient = make_config(tmp_path, OVERLAPPING + ACCEL + PRESS + cycles(WHL=10, ACC=10, PRESS=10), base_signals(),
                          strict=False, name="lenient")
    proc = check_config(lenient)
    assert proc.returncode == 0 and "strict=False" in proc.stdout
    _, _, report = replay_accuracy(lenient)
    assert report.valid_count > 50 and report.false_valid_count == 0


def test_several_dbc_files_for_one_vehicle(tmp_path):
    chassis = wheels_msg("km/h", 0.01) + cycles(WHL=10)
    brakes = ACCEL + PRESS + cycles(ACC=10, PRESS=20)
    path = make_config(tmp_path, [chassis, brakes], base_signals(), name="split")
    config = load_config(path)
    assert [p.name for p in config.can.dbc] == ["split0.dbc", "split1.dbc"]
    db = load_databases(config.can.dbc)
    assert {m.name for m in db.messages} == {"WHL", "ACC", "PRESS"}
    proc = check_config(path)
    assert proc.returncode == 0 and "split0.dbc" in proc.stdout and "split1.dbc" in proc.stdout
    assert "50 Hz" in proc.stdout
    _, _, report = replay_accuracy(path)
    assert report.valid_count > 50 and report.false_valid_count == 0 and report.mae < 0.03
    # A missing signal in either file is named; several at once are all named in one line.
    signals = base_signals()
    signals["accel_lat"] = "ACC.LatAccel"
    signals["brake_pressure_rr"] = "BRAKES.P_RR"
    proc = check_config(make_config(tmp_path, [chassis, brakes], signals, name="broken"))
    assert proc.returncode == 78
    (line,) = proc.stderr.strip().splitlines()
    assert "signals.accel_lat" in line and "'LatAccel'" in line and "signals.brake_pressure_rr" in line


def test_valid_status_reaches_the_bus_through_a_vehicle_dbc(tmp_path):
    # Sanity of the helpers above: the default DBC's names appear nowhere in these configs.
    path = make_config(tmp_path, wheels_msg("m/s", 0.005) + ACCEL + PRESS + cycles(WHL=10, ACC=10, PRESS=10),
                       base_signals())
    assert "WHEEL_SPEEDS" not in path.read_text()
    config = load_config(path)
    frames, _ = simulate_frames(config, "wet", seed=2)
    _, estimates = estimates_of(config, frames)
    assert any(e.status == Status.VALID for e in estimates)


def test_inputs_longer_than_eight_bytes_are_can_fd(tmp_path):
    classic = codec_for(make_config(tmp_path, wheels_msg() + ACCEL + PRESS, base_signals(), name="classic"))
    assert classic.fd is False
    long_wheels = wheels_msg().replace("BO_ 200 WHL: 8 ESC", "BO_ 200 WHL: 16 ESC")
    fd = codec_for(make_config(tmp_path, long_wheels + ACCEL + PRESS, base_signals(), name="fd"))
    assert fd.fd is True
    msg = fd.db.get_message_by_name("WHL")
    data = msg.encode({f"V_{w}": 12.5 for w in ("FL", "FR", "RL", "RR")})
    assert len(data) == 16 and fd.decode(Frame(0.0, 200, data)).values["wheel_speed_rr"] == pytest.approx(12.5)


def test_29_bit_inputs_are_read_and_an_11_bit_frame_of_the_same_number_is_not(tmp_path):
    extended_wheels = wheels_msg().replace("BO_ 200 WHL:", f"BO_ {0x80000000 | 200} WHL:")
    path = make_config(tmp_path, extended_wheels + ACCEL + PRESS, base_signals())
    codec = codec_for(path)
    assert codec.extended_input_ids == {200} and codec.trigger_extended
    data = codec.db.get_message_by_name("WHL").encode({f"V_{w}": 10.0 for w in ("FL", "FR", "RL", "RR")})
    assert codec.decode(Frame(0.0, 200, data, True)).values["wheel_speed_fl"] == pytest.approx(10.0)
    assert codec.decode(Frame(0.0, 200, data, False)) is None
    assert "0x000000C8 (29-bit)" in check_config(path).stdout
