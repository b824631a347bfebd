"""Cut the MRCLAM test excerpt in tests/data/mrclam_excerpt/ from a full MRCLAM dataset folder.

Usage: python tests/data/cut_mrclam_excerpt.py /path/to/MRCLAM_Dataset7 OUT_DIR [--robot 1] [--start 10]
       [--duration 40] [--odo-every 10] [--gt-every 6]

Lines are copied verbatim (the 4 header lines plus data lines). Barcodes.dat and Landmark_Groundtruth.dat are
copied whole. For RobotN_{Odometry,Groundtruth,Measurement}.dat only rows with a time stamp in
[t_first + start, t_first + start + duration] are kept (t_first = first odometry stamp), and of those only every
``odo-every``-th odometry row and every ``gt-every``-th ground-truth row, so each file stays a few hundred lines.
The thinned odometry is still a valid velocity log (the importer holds each row until the next one); the
measurement rows are all kept.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path


def _split(path: Path) -> tuple[list[str], list[str]]:
    lines = path.read_text().splitlines(keepends=True)
    head = [ln for ln in lines[:4] if ln.startswith("#")]
    return head, [ln for ln in lines[len(head):] if ln.strip()]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("src", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--robot", type=int, default=1)
    ap.add_argument("--start", type=float, default=10.0)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--odo-every", type=int, default=10)
    ap.add_argument("--gt-every", type=int, default=6)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    for name in ("Barcodes.dat", "Landmark_Groundtruth.dat"):
        shutil.copyfile(a.src / name, a.out / name)
    _, odo = _split(a.src / f"Robot{a.robot}_Odometry.dat")
    t_first = float(odo[0].split()[0])
    lo, hi = t_first + a.start, t_first + a.start + a.duration
    for kind, every in (("Odometry", a.odo_every), ("Groundtruth", a.gt_every), ("Measurement", 1)):
        head, rows = _split(a.src / f"Robot{a.robot}_{kind}.dat")
        rows = [r for r in rows if lo <= float(r.split()[0]) <= hi][::every]
        (a.out / f"Robot{a.robot}_{kind}.dat").write_text("".join(head + rows))
        print(f"Robot{a.robot}_{kind}.dat: {len(rows)} rows")


if __name__ == "__main__":
    main()
