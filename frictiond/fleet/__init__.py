"""Fleet replay: many logs through one estimator version on Dask, Parquet results, and their diff.

Modules: `stops` (braking stops of one replay), `results` (the Parquet result set), `run` (the
per-log task and the loop over an executor), `cluster` (Dask as a `concurrent.futures.Executor`,
reusable by other batch jobs), `diff` (two result sets, stop by stop). Needs the `fleet` extra
(dask[distributed], pyarrow) except `stops`; nothing here is imported by the daemon.
"""
