"""Cut a small excerpt of a landmark pose-graph file (g2o or GTSAM text) for the slamcli tests.

Usage: python tests/data/cut_graph_excerpt.py IN_FILE OUT_FILE --poses K

Keeps the first K poses of the odometry chain (EDGE_SE2 / ODOMETRY edges followed from the pose that no edge
reaches) and every line that refers only to them: their VERTEX_SE2 lines, the odometry edges between them, the
landmark observations (EDGE_SE2_XY / LANDMARK) taken from them and the VERTEX_XY lines of the landmarks those
observe. Lines are copied verbatim and in file order.
"""

from __future__ import annotations

import argparse
from pathlib import Path

ODO = ("EDGE_SE2", "ODOMETRY")
OBS = ("EDGE_SE2_XY", "LANDMARK")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("src", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--poses", type=int, required=True)
    a = ap.parse_args()
    lines = a.src.read_text().splitlines(keepends=True)
    nxt, reached = {}, set()
    for ln in lines:
        f = ln.split()
        if f and f[0] in ODO:
            nxt[f[1]] = f[2]
            reached.add(f[2])
    cur = next(i for i in nxt if i not in reached)
    keep = [cur]
    while len(keep) < a.poses and cur in nxt:
        cur = nxt[cur]
        keep.append(cur)
    poses = set(keep)
    landmarks = {ln.split()[2] for ln in lines if ln.split() and ln.split()[0] in OBS and ln.split()[1] in poses}
    out = []
    for ln in lines:
        f = ln.split()
        if not f:
            continue
        if (f[0] in ("VERTEX_SE2", "VERTEX2") and f[1] in poses) or (f[0] == "VERTEX_XY" and f[1] in landmarks) \
                or (f[0] in ODO and f[1] in poses and f[2] in poses) or (f[0] in OBS and f[1] in poses):
            out.append(ln)
    a.out.write_text("".join(out))
    print(f"{a.out}: {len(out)} lines, {len(poses)} poses, {len(landmarks)} landmarks")


if __name__ == "__main__":
    main()
