"""Cut the first K poses of a g2o pose graph with loop closures for the slamcli tests.

Usage: python tests/data/cut_pose_graph_excerpt.py IN_FILE OUT_FILE --poses K

Pose ids are those used by EDGE_SE2 lines, in ascending order (as ``slamcli import g2o`` orders them); the
first K are kept with their VERTEX_SE2 lines and every EDGE_SE2 line between two kept poses (odometry and
loop closures). Lines are copied verbatim and in file order.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("src", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--poses", type=int, required=True)
    a = ap.parse_args()
    lines = a.src.read_text().splitlines(keepends=True)
    ids = sorted({int(f[k]) for f in (ln.split() for ln in lines) if f and f[0] == "EDGE_SE2" for k in (1, 2)})
    keep = set(ids[: a.poses])
    out = []
    for ln in lines:
        f = ln.split()
        if f and f[0] == "VERTEX_SE2" and int(f[1]) in keep:
            out.append(ln)
        elif f and f[0] == "EDGE_SE2" and int(f[1]) in keep and int(f[2]) in keep:
            out.append(ln)
    a.out.write_text("".join(out))


if __name__ == "__main__":
    main()
