"""Codec: input decoding through the signal map, output encoding with E2E, round trips."""
from __future__ import annotations

import math

import cantools
import pytest

from frictiond.codec import DecodeFailure, InputCodec, OutputCodec, load_databases
from frictiond.config import ConfigError, load_config
from frictiond.e2e import E2EChecker, crc8_sae_j1850, e2e_crc
from frictiond.frames import Frame
from frictiond.samples import FrictionEstimate, PhysicalSample, Status

from .conftest import REPO, edited_dbc, write_config

DBC = REPO / "dbc" / "frictiond.dbc"


def codecs(config):
    db = load_databases(config.can.dbc)
    return InputCodec(db, config.signals, config.vehicle.wheel_radius), OutputCodec(load_databases([config.can.output_dbc]))


def test_crc8_sae_j1850_check_value():
    # The catalogue check value of CRC-8/SAE-J1850 (reveng): "123456789" -> 0x4B.
    assert crc8_sae_j1850(b"123456789") == 0x4B


def test_crc_covers_data_id_low_byte_first():
    payload = bytes([0, 1, 2, 3, 4, 5, 6, 7])
    assert e2e_crc(0x3E0, payload) == crc8_sae_j1850(bytes([0xE0, 0x03, 1, 2, 3, 4, 5, 6, 7]))
    assert e2e_crc(0x3E0, payload) != e2e_crc(0x3E1, payload)


def test_input_round_trip_in_si_units(default_config):
    inp, _ = codecs(default_config)
    values = {"wheel_speed_fl": 80.12, "wheel_speed_fr": 79.5, "wheel_speed_rl": 81.0, "wheel_speed_rr": 0.0}
    (payload,) = inp.encode_input("WHEEL_SPEEDS", values)
    decoded = inp.decode(Frame(1.5, 0x0B0, payload))
    assert decoded.is_trigger and decoded.message == "WHEEL_SPEEDS" and decoded.time_s == 1.5
    for k, v in values.items():
        assert decoded.values[k] == pytest.approx(v, abs=0.005)
    (payload,) = inp.encode_input("ACCELERATIONS", {"accel_long": -7.5, "accel_lat": 2.25, "yaw_rate": -0.3})
    decoded = inp.decode(Frame(2.0, 0x0C0, payload))
    assert not decoded.is_trigger
    assert decoded.values == pytest.approx({"accel_long": -7.5, "accel_lat": 2.25, "yaw_rate": -0.3}, abs=1e-3)


def test_decoding_agrees_with_cantools_directly(default_config):
    inp, _ = codecs(default_config)
    db = cantools.database.load_file(str(DBC))
    msg = db.get_message_by_name("BRAKE_PRESSURES")
    data = msg.encode({"BrakePressure_FL": 55.5, "BrakePressure_FR": 0.0, "BrakePressure_RL": 12.34, "BrakePressure_RR": 655.35})
    decoded = inp.decode(Frame(0.0, msg.frame_id, data))
    assert decoded.values["brake_pressure_fl"] == pytest.approx(55.5)
    assert decoded.values["brake_pressure_rl"] == pytest.approx(12.34)


def test_non_inputs_are_ignored_and_bad_inputs_fail_with_a_reason(default_config):
    inp, _ = codecs(default_config)
    assert inp.decode(Frame(0.0, 0x123, b"\x00" * 8)) is None
    assert inp.decode(Frame(0.0, 0x0B0, b"\x00" * 8, is_extended=True)) is None
    with pytest.raises(DecodeFailure) as info:
        inp.decode(Frame(0.0, 0x0B0, b"\x00" * 5))
    assert info.value.reason == "wrong length"


def test_unit_scale_and_sign_conversion(tmp_path, config_dict):
    # Decelerations sent positive and lateral acceleration in g, via config only.
    config_dict["signals"]["accel_long"].update(scale=-1.0)
    config_dict["signals"]["accel_lat"].update(unit="g")
    config_dict["signals"]["wheel_speed_fl"].update(unit="km/h")
    cfg = load_config(write_config(tmp_path, config_dict))
    inp, _ = codecs(cfg)
    db = cantools.database.load_file(str(DBC))
    acc = db.get_message_by_name("ACCELERATIONS").encode({"AccelLong": 6.0, "AccelLat": 0.5, "YawRate": 0.0})
    values = inp.decode(Frame(0.0, 0x0C0, acc)).values
    assert values["accel_long"] == pytest.approx(-6.0)
    assert values["accel_lat"] == pytest.approx(0.5 * 9.80665)
    ws = db.get_message_by_name("WHEEL_SPEEDS").encode(
        {"WheelSpeed_FL": 100.0, "WheelSpeed_FR": 0, "WheelSpeed_RL": 0, "WheelSpeed_RR": 0})
    values = inp.decode(Frame(0.0, 0x0B0, ws)).values
    assert values["wheel_speed_fl"] == pytest.approx(100.0 / 3.6 / cfg.vehicle.wheel_radius)
    # ... and the simulator's encoder inverts the same map.
    (payload,) = inp.encode_input("ACCELERATIONS", {"accel_long": -4.0, "accel_lat": 1.0, "yaw_rate": 0.1})
    back = inp.decode(Frame(0.0, 0x0C0, payload)).values
    assert back["accel_long"] == pytest.approx(-4.0, abs=1e-3) and back["accel_lat"] == pytest.approx(1.0, abs=0.01)


def test_output_frames_carry_contract_names_valid_crc_and_counter(default_config):
    _, out = codecs(default_config)
    db = cantools.database.load_file(str(DBC))
    est = FrictionEstimate(1.0, Status.VALID, 0.8123, 0.105, 1.5, 0.93, (0.8, 0.81, 0.82, 0.83))
    payloads = [out.encode_estimate(est) for _ in range(20)]
    for k, data in enumerate(payloads):
        decoded = db.decode_message("FRICTION_ESTIMATE", data)
        assert decoded["Counter"] == k % 16
        assert decoded["Crc"] == e2e_crc(0x3E0, data)
        assert str(decoded["EstimatorStatus"]) == "VALID"
        assert decoded["MuMax"] == pytest.approx(0.8123, abs=1e-4)
        assert decoded["SlipAtMuMax"] == pytest.approx(0.105, abs=1e-3)
        assert decoded["Theta"] == pytest.approx(1.5, abs=0.01)
        assert decoded["Confidence"] == pytest.approx(0.93, abs=0.005)
    sample = PhysicalSample(1.0, 20.0, (0.1, -0.05, 0.2, 0.0), (0.7, -0.3, 0.9, 0.0), (4000.0, 4100.0, 3000.0, 2900.0),
                            (0.0,) * 4, (True,) * 4, True)
    wheels = out.encode_wheels(est, sample)
    assert len(wheels) == 4
    for i, data in enumerate(wheels):
        decoded = db.decode_message("FRICTION_WHEEL", data, decode_choices=False)
        assert decoded["WheelIndex"] == i
        assert decoded["Counter"] == i
        assert decoded["Crc"] == e2e_crc(0x3E1, data)
        assert decoded["Slip"] == pytest.approx(sample.slip[i], abs=5e-4)
        assert decoded["MuUsed"] == pytest.approx(sample.mu_used[i], abs=1e-3)
        assert decoded["MuMaxWheel"] == pytest.approx(est.wheel_mu_max[i], abs=5e-4)
        assert decoded["NormalForce"] == pytest.approx(sample.normal_force_n[i], abs=5)


def test_non_finite_estimate_never_reaches_the_bus(default_config):
    _, out = codecs(default_config)
    db = cantools.database.load_file(str(DBC))
    for bad in (math.nan, math.inf, -math.inf):
        data = out.encode_estimate(FrictionEstimate(0.0, Status.VALID, bad, 0.1, 1.0, 0.9))
        decoded = db.decode_message("FRICTION_ESTIMATE", data, decode_choices=False)
        assert decoded["EstimatorStatus"] == Status.FAULT
        assert math.isfinite(decoded["MuMax"])


def test_out_of_range_values_are_clipped_not_wrapped(default_config):
    _, out = codecs(default_config)
    db = cantools.database.load_file(str(DBC))
    data = out.encode_estimate(FrictionEstimate(0.0, Status.VALID, 7.0, -0.5, 99.0, 3.0))
    decoded = db.decode_message("FRICTION_ESTIMATE", data, decode_choices=False)
    assert decoded["MuMax"] == pytest.approx(2.0) and decoded["SlipAtMuMax"] == 0.0
    assert decoded["Theta"] == pytest.approx(40.95) and decoded["Confidence"] == pytest.approx(1.0)


def test_e2e_checker_sees_corruption_and_loss(default_config):
    _, out = codecs(default_config)
    est = FrictionEstimate(0.0, Status.VALID, 0.5, 0.1, 2.0, 0.9)
    frames = [out.encode_estimate(est) for _ in range(6)]
    checker = E2EChecker()
    assert checker.check(0x3E0, frames[0]) == "ok"
    assert checker.check(0x3E0, frames[1]) == "ok"
    assert checker.check(0x3E0, frames[4]) == "jump" and checker.frames_lost == 2
    corrupt = bytearray(frames[5])
    corrupt[3] ^= 0x10
    assert checker.check(0x3E0, bytes(corrupt)) == "crc"
    assert checker.crc_failures == 1


def test_output_dbc_with_spare_signals_sends_them_idle(tmp_path):
    # A vehicle's own copy of the output messages may carry signals the contract does not name.
    path = edited_dbc(tmp_path, (
        ' SG_ Confidence : 54|8@1+ (0.005,0) [0|1] "" VEHICLE\n',
        ' SG_ Confidence : 54|8@1+ (0.005,0) [0|1] "" VEHICLE\n SG_ Spare : 62|2@1+ (1,1) [1|3] "" VEHICLE\n'))
    out = OutputCodec(load_databases([path]))
    data = out.encode_estimate(FrictionEstimate(0.0, Status.VALID, 0.8, 0.1, 1.0, 0.9))
    decoded = out.decode_output(Frame(0.0, out.estimate_id, data))
    assert decoded["e2e"] == "ok" and decoded["MuMax"] == pytest.approx(0.8) and decoded["Spare"] == 1


@pytest.mark.parametrize("edits", [
    [("Counter : 8|4@1+ (1,0) [0|15]", "Counter : 8|2@1+ (1,0) [0|3]")],                  # not a nibble
    [("Counter : 8|4@1+", "Counter : 13|4@1+"), ("EstimatorStatus : 12|4@1+", "EstimatorStatus : 8|4@1+"),
     ("MuMax : 16|16@1+", "MuMax : 17|15@1+")],                                               # across bytes
    [("Crc : 0|8@1+", "Crc : 7|8@0+")],                                                       # big-endian CRC
])
def test_output_dbc_whose_e2e_fields_cannot_be_written_is_refused(tmp_path, edits):
    path = edited_dbc(tmp_path, *edits)   # (each at its first place: FRICTION_ESTIMATE's)
    with pytest.raises(ConfigError, match="FRICTION_ESTIMATE needs Crc as 0"):
        OutputCodec(load_databases([path]))
