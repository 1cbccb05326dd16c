"""Why an estimate is not VALID: the estimator's own reason, and replay's sum of it over a log."""
from __future__ import annotations

import pytest

from frictiond import not_valid
from frictiond.estimator import LugreTrustRegionEstimator
from frictiond.pipeline import Pipeline
from frictiond.replay import replay_frames
from frictiond.samples import Status
from frictiond.sim_frames import simulate_frames


def test_a_wheel_verdict_loses_its_number_and_a_shortfall_says_what_it_missed():
    assert not_valid.wheel_verdict_words(("still rising ({:.2f})", 0.62)) == "still rising"
    assert not_valid.wheel_verdict_words("slip not running away") == "slip not running away"
    assert not_valid.wheel_verdict_words(("proximity {:.2f}", 0.6)) == "short of the fitted peak"
    assert not_valid.wheel_verdict_words("") == ""


def test_no_peak_shown_names_the_verdict_most_wheels_gave():
    whys = [("not bending ({:.2f})", 0.8), "slip not running away", ("not bending ({:.2f})", 0.7), ""]
    assert not_valid.not_excited_reason(whys) == f"{not_valid.NOT_EXCITED} (not bending)"
    assert not_valid.not_excited_reason(["", "", "", ""]) == not_valid.NOT_EXCITED


@pytest.mark.parametrize("bar, reason", [
    ("_stop_floor", not_valid.BELOW_STOP_FLOOR),
    ("_misfit", not_valid.MISFIT),
    ("_leans_on_unshown_wheels", not_valid.UNSHOWN_WHEELS),
])
def test_a_confident_estimate_that_a_bar_holds_back_says_which_bar(monkeypatch, bar, reason):
    est = LugreTrustRegionEstimator()
    numbers = (0.8, 0.1, 1.2, (0.8, 0.8, 0.8, 0.8), 0.01, {})
    est._last_estimate = est._decided(1.0, 20.0, 1.0, 0.9, numbers)
    assert est._last_estimate.status == Status.VALID and est.not_valid_reason == ""
    values = {"_stop_floor": lambda: 2.0, "_misfit": lambda now_s: True,
              "_leans_on_unshown_wheels": lambda now_s, wheel_mu: True}
    monkeypatch.setattr(est, bar, values[bar])
    est._last_estimate = est._decided(1.1, 20.0, 1.0, 0.9, numbers)
    assert est._last_estimate.status == Status.CONVERGING
    assert est.not_valid_reason == reason


def test_an_unexcited_or_unsure_estimate_says_so():
    est = LugreTrustRegionEstimator()
    numbers = (0.8, 0.1, 1.2, (0.8, 0.8, 0.8, 0.8), 0.01, {})
    est._excitation_why = ["slip not running away"] * 4
    est._last_estimate = est._decided(1.0, 20.0, 0.0, 0.0, numbers)
    assert est.not_valid_reason == f"{not_valid.NOT_EXCITED} (slip not running away)"
    est._last_estimate = est._decided(1.1, 20.0, 1.0, 0.3, numbers)
    assert est.not_valid_reason == not_valid.LOW_CONFIDENCE


def test_the_replay_summary_says_why_a_stop_below_the_peak_stayed_unsure(default_config):
    # Firm braking on a wet road without ABS: the tyres never reach their peak, nothing is VALID,
    # and the summary says the estimator saw no peak for about as long as the car braked.
    frames, sim = simulate_frames(default_config, "moderate_wet", seed=1)
    pipeline = Pipeline(default_config)
    text = replay_frames(pipeline, frames).format()
    counts = pipeline.stats.estimator_not_valid
    assert pipeline.stats.status_updates[Status.VALID] == 0
    unexcited = sum(n for reason, n in counts.items() if reason.startswith(not_valid.NOT_EXCITED))
    assert unexcited > 0.5 * sum(counts.values()) > 0
    assert "why not VALID" in text and not_valid.NOT_EXCITED in text


def test_a_stop_valid_throughout_its_abs_has_little_to_explain(default_config):
    frames, _ = simulate_frames(default_config, "dry", seed=1)
    pipeline = Pipeline(default_config)
    replay_frames(pipeline, frames)
    valid = pipeline.stats.status_updates[Status.VALID]
    assert valid > 0 and sum(pipeline.stats.estimator_not_valid.values()) < 0.5 * valid


def test_the_pipeline_names_corrupt_input_as_its_reason(default_config):
    from frictiond import corruption, input_quality
    from frictiond.sim_frames import input_codec_for

    frames, _ = simulate_frames(default_config, "wet", seed=1)
    damaged, _ = corruption.corrupt("random payload", frames, input_codec_for(default_config), 0.12, seed=3)
    pipeline = Pipeline(default_config)
    reasons = set()
    for frame in damaged:
        pipeline.process(frame)
        reasons.add(pipeline.not_valid_reason)
    assert input_quality.REASON in reasons
