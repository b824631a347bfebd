"""Cut tests/data/carpark_excerpt/ from $SLAMCLI_DATASETS/acfr_carpark (first 150 laser scans, ~32 s).

Run once: ``.venv/bin/python tests/data/cut_carpark_excerpt.py``. Rows are copied unmodified; only the time
window is cut (every sensor array up to the time of scan 60), the merged event list is left out (the importer
does not read it) and beac_juan3.mat is copied whole.
"""

import os
import shutil
import sys
from pathlib import Path

import scipy.io as sio

SRC = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(os.environ["SLAMCLI_DATASETS"]) / "acfr_carpark"
DST = Path(__file__).parent / "carpark_excerpt"
N_SCANS = 150

m = sio.loadmat(SRC / "data_set.mat")
t_end = float(m["TimeLaser"].ravel()[N_SCANS - 1]) + 0.05
out = {}
for key_t, keys in (("TimeLaser", ("Laser", "Intensity")), ("Time_VS", ("Velocity", "Steering")),
                    ("TimeGPS", ("GPSLon", "GPSLat"))):
    t = m[key_t].ravel()
    keep = t <= t_end
    out[key_t] = m[key_t][:, keep]
    for k in keys:
        out[k] = m[k][keep] if m[k].shape[0] == t.size and m[k].ndim == 2 and m[k].shape[1] == 361 else m[k][:, keep]
DST.mkdir(exist_ok=True)
sio.savemat(DST / "data_set.mat", out, do_compression=True)
shutil.copy(SRC / "beac_juan3.mat", DST / "beac_juan3.mat")
print({k: v.shape for k, v in out.items()})
