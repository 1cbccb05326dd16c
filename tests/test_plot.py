"""Replay plots: the image exists, has the requested size, and each format is what it says."""
from __future__ import annotations

import argparse
import math
import struct
import sys
import xml.etree.ElementTree as ET

import pytest

from frictiond import plot
from frictiond import tyre_model as tm
from frictiond.busio import LogWriter
from frictiond.codec import InputCodec, load_databases
from frictiond.estimator import LugreTrustRegionEstimator
from frictiond.frames import Frame
from frictiond.replay import ReplayRecorder
from frictiond.samples import PhysicalSample, Status

matplotlib = pytest.importorskip("matplotlib")


def png_size(path) -> tuple[int, int]:
    data = path.read_bytes()[:33]
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    length, kind = struct.unpack(">I4s", data[8:16])
    assert kind == b"IHDR" and length == 13
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def fitted_replay():
    """A recorder and a LuGre estimator fitted on ABS-like braking on a known road (no CAN)."""
    p = tm.LugreParams(theta=1.4)
    est = LugreTrustRegionEstimator()
    rec = ReplayRecorder()
    t, v = 0.0, 25.0
    while t < 2.0:
        lam_star = tm.peak(v, p)[1]
        slips = tuple(float(lam_star * (1.0 + 0.55 * math.sin(2 * math.pi * 3.0 * t + i))) for i in range(4))
        mus = tuple(float(tm.mu(s, v, p)) for s in slips)
        # (ABS cycling: the front end would flag the releases from the pressures)
        sample = PhysicalSample(t, v, slips, mus, (4000.0,) * 4, (0.0,) * 4, (True,) * 4, True,
                                abs_active=(True,) * 4)
        rec.record(est.update(sample), sample)
        v -= 0.08
        t += 0.01
    return rec, est, p


def write_truth(path, rec, p, offset=0.0):
    with open(path, "w") as fh:
        fh.write("time_s,mu_max,slip_fl,slip_fr,slip_rl,slip_rr,scenario\n")
        for s in rec.samples[::5]:
            mu_max = tm.peak(s.speed_mps, p)[0]
            fh.write(f"{s.time_s + offset},{mu_max},{s.slip[0]},{s.slip[1]},{s.slip[2]},{s.slip[3]},dry\n")


def test_png_has_the_requested_pixel_size(tmp_path, fitted_replay):
    rec, est, p = fitted_replay
    assert any(e.status == Status.VALID for e in rec.estimates)
    truth = tmp_path / "truth.csv"
    write_truth(truth, rec, p)
    out = plot.plot_replay(rec, tmp_path / "replay.png", truth_path=truth, estimator=est, pixels=(1234, 777))
    assert out.is_file()
    assert png_size(out) == (1234, 777)
    out = plot.plot_replay(rec, tmp_path / "inches.png", size=(6.4, 4.8), dpi=50)
    assert png_size(out) == (320, 240)


def test_size_for_pixels_is_exact_at_any_dpi(tmp_path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    for (w, h), dpi in (((641, 479), 100), ((1000, 333), 72), ((1920, 1080), 96), ((777, 101), 150)):
        fig = Figure(figsize=plot.size_for_pixels(w, h, dpi), dpi=dpi)
        FigureCanvasAgg(fig).draw()
        assert fig.canvas.get_width_height() == (w, h)
        path = tmp_path / f"{w}x{h}.png"
        fig.savefig(path, dpi=dpi)
        assert png_size(path) == (w, h)


def test_svg_parses_and_pdf_is_a_pdf(tmp_path, fitted_replay):
    rec, est, p = fitted_replay
    truth = tmp_path / "truth.csv"
    write_truth(truth, rec, p, offset=1.7e9)   # truth on another clock: aligned to the log's start
    svg = plot.plot_replay(rec, tmp_path / "replay.svg", truth_path=truth, estimator=est)
    root = ET.parse(svg).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    assert "MuMax" in svg.read_text()
    pdf = plot.plot_replay(rec, tmp_path / "replay.pdf", estimator=est)
    assert pdf.read_bytes()[:5] == b"%PDF-"


def test_an_empty_replay_still_draws(tmp_path):
    out = plot.plot_replay(ReplayRecorder(), tmp_path / "empty.png", pixels=(400, 300))
    assert png_size(out) == (400, 300)


def test_size_and_format_checks():
    assert plot.parse_size("1200x800") == (1200, 800)
    assert plot.parse_size("640×480") == (640, 480)
    for bad in ("1200", "axb", "10x10", "1200x800x3"):
        with pytest.raises(ValueError):
            plot.parse_size(bad)
    plot.check_plot_path("a.png")
    plot.check_plot_path("a.SVG")
    with pytest.raises(ValueError, match="unknown image format"):
        plot.check_plot_path("a.xyz")


# ---------------------------------------------------------------------------- through the CLI
def replay_cli(argv):
    from frictiond.cli import replay

    parser = argparse.ArgumentParser(prog="frictiond")
    replay.add_subparser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["replay", *argv])
    return args.func(args)


@pytest.fixture
def input_log(tmp_path, default_config):
    """One second of gentle braking as input frames (enough for the pipeline to run, not to converge)."""
    codec = InputCodec(load_databases(default_config.can.dbc), default_config.signals,
                       default_config.vehicle.wheel_radius)
    ids = {m.name: m.frame_id for m in codec.input_messages()}
    path = tmp_path / "inputs.log"
    with LogWriter(path) as writer:
        for k in range(100):
            t = 10.0 + 0.01 * k
            v = 20.0 - 2.0 * 0.01 * k
            omega = v / default_config.vehicle.wheel_radius
            for name, values in (
                ("WHEEL_SPEEDS", {f"wheel_speed_{w}": omega * 0.98 for w in ("fl", "fr", "rl", "rr")}),
                ("ACCELERATIONS", {"accel_long": -2.0, "accel_lat": 0.0, "yaw_rate": 0.0}),
                ("BRAKE_PRESSURES", {f"brake_pressure_{w}": 10.0 for w in ("fl", "fr", "rl", "rr")}),
                ("VEHICLE_SPEED_REF", {"vehicle_speed_ref": v}),
                ("WHEEL_DRIVE_TORQUE", {f"drive_torque_{w}": 0.0 for w in ("fl", "fr", "rl", "rr")}),
            ):
                for payload in codec.encode_input(name, values):
                    writer.write(Frame(t, ids[name], payload))
    return path


def test_replay_cli_plots_at_the_requested_size(tmp_path, input_log, capsys):
    out = tmp_path / "plot.png"
    assert replay_cli([str(input_log), "--plot", str(out), "--plot-size", "640x480", "--quiet"]) == 0
    assert png_size(out) == (640, 480)
    assert replay_cli([str(input_log), "--plot", str(tmp_path / "plot.svg"), "--quiet"]) == 0
    ET.parse(tmp_path / "plot.svg")


def test_replay_cli_rejects_bad_plot_options(tmp_path, input_log, capsys):
    assert replay_cli([str(input_log), "--plot", str(tmp_path / "p.xyz")]) == 2
    assert "unknown image format" in capsys.readouterr().err
    assert replay_cli([str(input_log), "--plot", str(tmp_path / "p.png"), "--plot-size", "big"]) == 2
    assert "WIDTHxHEIGHT" in capsys.readouterr().err


def test_without_matplotlib_the_cli_says_how_to_install_it(tmp_path, input_log, capsys, monkeypatch):
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)   # import matplotlib -> ImportError
    assert not plot.plotting_available()
    code = replay_cli([str(input_log), "--plot", str(tmp_path / "p.png")])
    assert code != 0
    assert "pip install 'frictiond[plot]'" in capsys.readouterr().err
    assert not (tmp_path / "p.png").exists()
