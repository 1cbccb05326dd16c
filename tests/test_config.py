"""Config validation: every bad input names its key; the CLIs exit 78 with one line."""
from __future__ import annotations

import subprocess
import sys

import pytest

from frictiond.config import ConfigError, load_config
from frictiond.pipeline import Pipeline

from .conftest import REPO, write_config


def test_default_config_loads_and_resolves_relative_dbc(default_config):
    assert default_config.can.dbc[0].name == "frictiond.dbc"
    assert default_config.can.dbc[0].is_file()
    assert default_config.estimator.kind == "lugre-tr"
    assert default_config.vehicle.mass == 1500.0
    assert set(default_config.signals) >= {"wheel_speed_fl", "accel_long", "brake_pressure_rr"}


def test_repo_config_is_the_packaged_one():
    assert (REPO / "config" / "frictiond.yaml").read_text() == (REPO / "frictiond" / "data" / "frictiond.yaml").read_text()
    assert (REPO / "dbc" / "frictiond.dbc").read_text() == (REPO / "frictiond" / "data" / "frictiond.dbc").read_text()


def test_relative_dbc_path_resolves_against_config_folder(tmp_path, config_dict):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "car.dbc").write_text(open(config_dict["can"]["dbc"]).read())
    config_dict["can"]["dbc"] = "car.dbc"
    cfg = load_config(write_config(tmp_path / "sub", config_dict))
    assert cfg.can.dbc == ((tmp_path / "sub" / "car.dbc").resolve(),)


def test_a_car_whose_air_drag_is_not_given_is_taken_as_any_car_with_that_doubt(tmp_path, config_dict):
    # Given, the drag is the car's; not given, it is the middle of what cars and simulators without
    # air have, 0 to 0.7 kg/m, and doubted by half of that range. (No wind unless one is given.)
    given = load_config(write_config(tmp_path, config_dict)).vehicle
    assert (given.drag_area_coefficient, given.drag_area_doubt, given.wind_doubt) == (0.4, 0.0, 0.0)
    del config_dict["vehicle"]["drag_area_coefficient"]
    unknown = load_config(write_config(tmp_path, config_dict)).vehicle
    assert (unknown.drag_area_coefficient, unknown.drag_area_doubt) == (0.35, 0.35)
    assert unknown.resistance_doubt_n(30.0) == pytest.approx(0.35 * 30.0**2)
    config_dict["vehicle"]["drag_area_doubt"] = 0.1
    assert load_config(write_config(tmp_path, config_dict)).vehicle.drag_area_doubt == 0.1


BAD = [
    (lambda d: d["vehicle"].update(mass=-1500), "vehicle.mass"),
    (lambda d: d["vehicle"].update(mass="heavy"), "vehicle.mass"),
    (lambda d: d["vehicle"].update(wheel_radius=0), "vehicle.wheel_radius"),
    (lambda d: d["vehicle"].update(colour="red"), "vehicle.colour"),
    (lambda d: d["vehicle"].update(wind_doubt=-1), "vehicle.wind_doubt"),
    (lambda d: d["vehicle"].update(drag_area_doubt=float("nan")), "vehicle.drag_area_doubt"),
    (lambda d: d["vehicle"].pop("mass") and d.pop("vehicle"), "vehicle: missing"),
    (lambda d: d.update(extra={}), "extra: unknown section"),
    (lambda d: d["estimator"].update(kind="kalman"), "estimator.kind"),
    (lambda d: d["estimator"].update(lugre_tr={"window_s": -1}), "estimator.lugre_tr"),
    (lambda d: d["estimator"].update(lugre_tr={"windw_s": 1}), "estimator.lugre_tr.windw_s"),
    (lambda d: d["estimator"].update(lugre_tr={"windw_s": 1}), "did you mean window_s"),
    (lambda d: d["vehicle"].update(colour="red"), "known: brake_gain_front"),   # a short section: listed
    (lambda d: d["estimator"].update(lugre_tr={"speed": 1}), "LugreTROptions"),   # a long one: named
    (lambda d: d["can"].update(dbc="/nonexistent/car.dbc"), "can.dbc"),
    (lambda d: d["can"].update(dbc=[]), "can.dbc"),
    (lambda d: d["can"].update(dbc_strict="yes"), "can.dbc_strict"),
    (lambda d: d["signals"].pop("wheel_speed_fl"), "wheel_speed_fl"),
    (lambda d: d["signals"].update(wheel_speed_xx={"message": "A", "signal": "B"}), "signals.wheel_speed_xx"),
    (lambda d: d["signals"].update(accel_long={"message": "ACCELERATIONS"}), "signals.accel_long.signal"),
    (lambda d: d["signals"].update(accel_long={"message": "ACCELERATIONS", "signal": "AccelLong", "scale": 0}), "scale"),
    (lambda d: d["output"].update(wheel_divider=0), "output.wheel_divider"),
    (lambda d: d["frontend"] if "frontend" in d else d.update(frontend={"min_speed": "x"}), "frontend.min_speed"),
    (lambda d: d.setdefault("frontend", {}).update(released_wheel_s=-0.5), "released_wheel_s"),
    (lambda d: d.setdefault("frontend", {}).update(released_min_slip=1.5), "released_min_slip"),
    (lambda d: d.setdefault("frontend", {}).update(released_min_slip=-0.1), "released_min_slip"),
]


@pytest.mark.parametrize("mutate,needle", BAD)
def test_bad_configs_name_the_key(tmp_path, config_dict, mutate, needle):
    mutate(config_dict)
    with pytest.raises(ConfigError) as info:
        load_config(write_config(tmp_path, config_dict))
    assert needle in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    "text,needle",
    [
        ("can: [1, 2\n", "invalid YAML"),
        ("- just\n- a list\n", "top level"),
        ("", "top level"),
        ("a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
         "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
         "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: [*e, *e, *e, *e, *e, *e, *e, *e, *e]\n", "too large"),
        ("can: !!python/object/apply:os.system ['echo pwned']\n", "invalid YAML"),
    ],
)
def test_hostile_yaml_is_refused(tmp_path, text, needle):
    with pytest.raises(ConfigError) as info:
        load_config(write_config(tmp_path, text))
    assert needle in str(info.value)


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(ConfigError, match="no such config file"):
        load_config(tmp_path / "nope.yaml")
    with pytest.raises(ConfigError, match="is a directory"):
        load_config(tmp_path)
    (tmp_path / "bin.yaml").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ConfigError, match="UTF-8"):
        load_config(tmp_path / "bin.yaml")


def test_signal_missing_from_dbc_stops_pipeline(tmp_path, config_dict):
    config_dict["signals"]["accel_long"] = {"message": "ACCELERATIONS", "signal": "AccelLongitudinal"}
    cfg = load_config(write_config(tmp_path, config_dict))
    with pytest.raises(ConfigError, match="AccelLongitudinal"):
        Pipeline(cfg)
    config_dict["signals"]["accel_long"] = {"message": "ACCEL_MISSING", "signal": "AccelLong"}
    with pytest.raises(ConfigError, match="ACCEL_MISSING"):
        Pipeline(load_config(write_config(tmp_path, config_dict)))


def test_dbc_that_does_not_parse(tmp_path, config_dict):
    (tmp_path / "broken.dbc").write_text("BO_ 176 WHEEL_SPEEDS: 8 VEHICLE\n SG_ Broken : x|y@1+ (a,b) [0|1] \"\" X\n")
    config_dict["can"]["dbc"] = str(tmp_path / "broken.dbc")
    with pytest.raises(ConfigError, match="broken.dbc"):
        Pipeline(load_config(write_config(tmp_path, config_dict)))


def test_unit_that_is_not_a_speed(tmp_path, config_dict):
    config_dict["signals"]["wheel_speed_fl"]["unit"] = "bar"
    with pytest.raises(ConfigError, match="signals.wheel_speed_fl"):
        Pipeline(load_config(write_config(tmp_path, config_dict)))


@pytest.mark.parametrize("command", [["replay", "x.log"], ["simulate", "--output", "x.log"]])
def test_cli_exits_78_with_one_line(tmp_path, config_dict, command):
    config_dict["vehicle"]["mass"] = -1
    cfg = write_config(tmp_path, config_dict)
    proc = subprocess.run([sys.executable, "-m", "frictiond.cli.main", *command, "--config", str(cfg)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=60)
    assert proc.returncode == 78
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "vehicle.mass" in lines[0] and "Traceback" not in proc.stderr
