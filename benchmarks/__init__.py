"""Speed and memory benchmarks. Run all with ``make bench`` (``python -m benchmarks``) or one with
``python -m benchmarks NAME``. Each ``bench_<name>.py`` exposes ``run(quick: bool = False) -> list[dict]``;
every dict is one row of the results table written to ``benchmarks/results/<name>.csv``."""
