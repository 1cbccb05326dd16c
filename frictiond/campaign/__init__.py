"""Randomised braking campaign (issue 21): random stops from documented ranges, truth models
independent of the estimator's, run through the real replay pipeline with both estimators.

- `draw.draw_stop(seed, family=None, stress=None) -> StopSpec` (ranges in draw.py's docstring; `draw.Stress`: what a stress run sets in place of the draw)
- `simulate.simulate_stop(spec) -> CampaignStop` (frames, truth rows, config)
- `score.score_stop(stop) -> dict` (metrics of both estimators), `run_campaign(...)` in `run.py`
"""
