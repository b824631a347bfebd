"""SLAM solvers. Each module holds one algorithm; all are found through the ``slamcli.solvers`` entry points.

Solvers import no typer, rich or h5py and never see ground truth.
"""
