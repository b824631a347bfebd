"""Cut the five-robot MRCLAM test excerpt in tests/data/mrclam_team_excerpt/ from a full MRCLAM dataset folder.

Usage: python tests/data/cut_mrclam_team_excerpt.py /path/to/MRCLAM_Dataset7 OUT_DIR [--start 300]
       [--duration 40] [--odo-every 10] [--gt-every 10]

As tests/data/cut_mrclam_excerpt.py, but for every RobotN_*.dat in the folder and ONE absolute window for all
robots: [t_first + start, t_first + start + duration] with t_first = robot 1's first odometry stamp. Lines are
copied verbatim (4 header lines + data lines); Barcodes.dat and Landmark_Groundtruth.dat whole; every
``odo-every``-th odometry and ``gt-every``-th ground-truth row; all measurement rows of the window.
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
    ap.add_argument("--start", type=float, default=300.0)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--odo-every", type=int, default=10)
    ap.add_argument("--gt-every", type=int, default=10)
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    for name in ("Barcodes.dat", "Landmark_Groundtruth.dat"):
        shutil.copyfile(a.src / name, a.out / name)
    _, odo = _split(a.src / "Robot1_Odometry.dat")
    t_first = float(odo[0].split()[0])
    lo, hi = t_first + a.start, t_first + a.start + a.duration
    robots = sorted(int(p.name[5:].split("_")[0]) for p in a.src.glob("Robot*_Odometry.dat"))
    for robot in robots:
        for kind, every in (("Odometry", a.odo_every), ("Groundtruth", a.gt_every), ("Measurement", 1)):
            head, rows = _split(a.src / f"Robot{robot}_{kind}.dat")
            rows = [r for r in rows if lo <= float(r.split()[0]) <= hi][::every]
            (a.out / f"Robot{robot}_{kind}.dat").write_text("".join(head + rows))
            print(f"Robot{robot}_{kind}.dat: {len(rows)} rows")


if __name__ == "__main__":
    main()
