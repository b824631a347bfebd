"""slamcli: a command-line experiment runner for 2-D SLAM research.

Importing this package is cheap on purpose (no numpy, no h5py): ``slamcli --help`` must answer fast.
"""

__version__ = "0.1.0"
