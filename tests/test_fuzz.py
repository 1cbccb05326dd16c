"""Property tests: hostile frames and samples never crash, never put NaN/inf on the bus."""
from __future__ import annotations

import math

import cantools
import numpy as np
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from frictiond.codec import DecodeFailure
from frictiond.estimator import LugreTrustRegionEstimator
from frictiond.frames import Frame
from frictiond.pipeline import Pipeline
from frictiond.samples import PhysicalSample, Status
from frictiond.sim_frames import simulate_frames

from .conftest import REPO

DBC = cantools.database.load_file(str(REPO / "dbc" / "frictiond.dbc"))
INPUT_IDS = [0x0B0, 0x0C0, 0x0D0, 0x0E0, 0x0F0]
SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def check_outputs(frames):
    for f in frames:
        assert f.can_id in (0x3E0, 0x3E1) and len(f.data) == 8
        values = DBC.decode_message(f.can_id, f.data, decode_choices=False)
        assert all(math.isfinite(v) for v in values.values())
        if f.can_id == 0x3E0:
            assert 0 <= values["EstimatorStatus"] <= 5


payloads = st.binary(min_size=0, max_size=12)
markers = st.sampled_from([b"\xff" * 8, b"\x00" * 8, b"\xff\xff" * 4, b"\x7f\xff" * 4, b"\x80\x00" * 4])


@SETTINGS
@given(st.sampled_from(INPUT_IDS), st.one_of(payloads, markers))
def test_codec_decodes_or_refuses_with_a_reason(default_config, can_id, data):
    pipeline = Pipeline(default_config)
    try:
        decoded = pipeline.input_codec.decode(Frame(1.0, can_id, data))
    except DecodeFailure as exc:
        assert exc.reason in ("wrong length", "out of range", "undecodable", "not finite")
        return
    assert decoded is not None
    assert all(math.isfinite(v) for v in decoded.values.values())


frame_strategy = st.builds(
    Frame,
    time_s=st.one_of(st.floats(-1e6, 1e7, allow_nan=False), st.just(math.nan), st.just(math.inf)),
    can_id=st.one_of(st.sampled_from(INPUT_IDS), st.integers(0, 0x7FF), st.integers(0, 0x1FFFFFFF)),
    data=st.one_of(payloads, markers),
    is_extended=st.booleans(),
    is_error=st.booleans(),
    is_remote=st.booleans(),
)


@SETTINGS
@given(st.lists(frame_strategy, min_size=1, max_size=60))
def test_pipeline_survives_arbitrary_frames(default_config, frames):
    pipeline = Pipeline(default_config)
    for f in frames:
        check_outputs(pipeline.process(f))
    if all(math.isfinite(f.time_s) for f in frames):
        check_outputs(pipeline.tick(max(f.time_s for f in frames) + 1.0))


@settings(max_examples=25, deadline=None, derandomize=True, phases=[Phase.explicit, Phase.generate],
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.integers(0, 10_000), st.floats(-7200.0, 7200.0), st.integers(0, 2))
def test_real_drive_with_spliced_junk_and_time_jumps_recovers(default_config, seed, jump_s, mode):
    frames, sim = simulate_frames(default_config, "wet", seed=seed % 7)
    rng = np.random.default_rng(seed)
    cut = len(frames) // 3
    junk = []
    for _ in range(200):
        cid = int(rng.choice(INPUT_IDS))
        junk.append(Frame(frames[cut].time_s, cid, bytes(rng.integers(0, 256, int(rng.integers(0, 9))).tolist())))
    if mode == 0:   # time jumps (clock step), then continues
        tail = [f._replace(time_s=f.time_s + jump_s) for f in frames[cut:]]
    elif mode == 1:  # duplicated and reordered frames
        tail = list(frames[cut:])
        for k in range(0, len(tail) - 1, 17):
            tail[k], tail[k + 1] = tail[k + 1], tail[k]
        tail = [f for f in tail for _ in (0, 1)][: len(tail) + 300]
    else:           # a burst: the same frames again in one instant
        tail = [f._replace(time_s=frames[cut].time_s) for f in frames[cut:cut + 100]] + list(frames[cut:])
    pipeline = Pipeline(default_config)
    statuses = []
    for f in frames[:cut] + junk + tail:
        out = pipeline.process(f)
        check_outputs(out)
        if out:
            statuses.append(pipeline.last_estimate.status)
    assert Status.INIT in statuses or Status.NOT_EXCITED in statuses
    # good data returned after the damage: the estimator is VALID again by the end of the stop
    assert Status.VALID in statuses[len(statuses) // 2:]


finite_or_not = st.one_of(st.floats(-1e9, 1e9, allow_nan=False), st.sampled_from([math.nan, math.inf, -math.inf]))
quad = st.tuples(finite_or_not, finite_or_not, finite_or_not, finite_or_not)


@SETTINGS
@given(st.lists(st.tuples(finite_or_not, quad, quad, st.tuples(*[st.booleans()] * 4)), min_size=1, max_size=40))
def test_estimator_never_reports_non_finite_numbers(rows):
    est = LugreTrustRegionEstimator()
    t = 0.0
    for speed, slip, mu, usable in rows:
        t += 0.01
        e = est.update(PhysicalSample(t, speed, slip, mu, (4000.0,) * 4, (0.0,) * 4, usable, True))
        assert e.status in Status.__members__.values()
        if e.status == Status.VALID:
            assert math.isfinite(e.mu_max) and math.isfinite(e.confidence)
