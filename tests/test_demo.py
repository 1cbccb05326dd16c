"""The built-in demo end to end: simulated frames over a python-can virtual bus, the daemon's
loop in its thread, and the estimate frames decoded back (what README's first command runs)."""
from __future__ import annotations

import io

from frictiond.config import default_config_path, load_config
from frictiond.demo import run_demo


def test_the_demo_reads_back_a_valid_estimate_near_the_truth_for_each_scenario():
    out = io.StringIO()
    results = run_demo(load_config(default_config_path()), ["dry", "snow"], pace=20.0, channel="test-demo", out=out)
    assert [r.scenario for r in results] == ["dry", "snow"]
    for r in results:
        assert r.final_status == "VALID"
        assert abs(r.mu_max - r.truth_mu_max) <= 0.1 * r.truth_mu_max
    # The progress table printed the decoded frames beside the truth for both scenarios.
    text = out.getvalue()
    assert "== dry" in text and "== snow" in text and text.count("VALID") >= 2
    # Each row's estimate stands beside the truth at its own time, and a scenario's rows show only
    # its own estimates: every VALID row within 10 % of the truth beside it. (The daemon falls
    # behind the frames sent; beside the truth of the newest frame sent, snow's rows were 12 % low,
    # and its first row showed the previous scenario's estimate.)
    rows = [line.split() for line in text.splitlines() if len(line.split()) == 6 and line.split()[2] == "VALID"]
    assert len(rows) > 20
    for _t, _v, _status, mu_max, _conf, truth in rows:
        assert abs(float(mu_max) - float(truth)) <= 0.1 * float(truth), (mu_max, truth)
