"""Paper reproductions: the top application layer, above the generic sweep engine.

* :mod:`~slamcli.reproduce.report`      the ``slamcli reproduce`` driver: sections → figures + REPORT.md
* :mod:`~slamcli.reproduce.outcomes`    every outcome sentence, computed from the numbers of the run
* :mod:`~slamcli.reproduce.paper001`    paper 001 (hybrid occupancy grid) sections
* :mod:`~slamcli.reproduce.paper004`    paper 004 (CuikSLAM) section
* :mod:`~slamcli.reproduce.real`        the real-recordings section
* :mod:`~slamcli.reproduce.real_multi`  the multi-robot (MRCLAM) section

These modules may import every lower layer (sweep, api, plots, metrics, io, solvers, sim); nothing below imports
them (``tests/meta/test_layering.py``). Importing this package is cheap: the modules are imported on use.
"""
