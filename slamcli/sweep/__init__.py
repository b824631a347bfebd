"""Parameter sweeps: experiment files → resolved runs → parallel, resumable, fail-soft execution.

Flow (each arrow is a module boundary)::

    experiments/X.toml --config.load_experiment--> ExperimentConfig
        --expand.expand--> Expansion (RunSpec list grouped by shared DatasetSpec)
        --runner.run_sweep--> results/<experiment>/<run_id>/ + manifest.csv + results.csv/.parquet

The paper reproductions that drive this engine live one layer up, in :mod:`slamcli.reproduce`; the summary
statistics of a finished sweep in :mod:`slamcli.metrics.aggregate`. Importing this package is cheap (no numpy,
no h5py); the heavy parts are imported by the modules that need them.
"""

from __future__ import annotations

__all__ = ["config", "expand", "runner"]
