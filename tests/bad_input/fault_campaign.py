"""The fault campaign of issue 23 ("nothing lost, ever"), re-runnable: ``python -m benchmarks.faults`` prints
its totals, ``tests/bad_input/test_bad_input_faults.py`` asserts them.

Families (each case one CLI invocation in a forked child of :class:`test_bad_input_helpers.CliServer`):

guard     an output that is an input (direct, symlink, hard link, ``x/..`` alias, relative), a file inside an
          input folder, a device / FIFO / socket, a path inside a running sweep's folder, a file of another
          kind: exit 2, the input byte-identical.
disk      a full 256 kB tmpfs (when this process may mount one) and a size-limited file (RLIMIT_FSIZE in the
          child): exit != 0, one line naming the file, no temporary, an existing output left as it was.
import    Victoria Park bearings outside the field of view, ranges <= 0; car park --max-range <= 0; mrclam
          --dt bounds.
implicit  outputs over files a command reads without naming them: the dataset a result records (export to
          every format, plot, evaluate), registry recordings' folders (importers by name, with --force, and
          any writer), a user folder given to evaluate -o, existing --solo-dir files: exit != 0, no --force
          suggested for an input, the file byte-identical.
wrong     the last tracebacks and wrong successes: importers writing what their reader refuses (values of 1e300,
          NaN noise, --dt 1e-320), g2o σ = 1e-200, GPS time running backwards, a MAT array of strings, a MAT
          zlib bomb, simulate/evaluate values of 1e300, symbolic link loops in -o, negative plot options.
registry  hostile registry entries: a marker or folder leaving the data folder (``../../etc/passwd``, ``/etc``,
          ``..``), control characters in a name, a 100,000-deep registry TOML or registered.json.
names     file names that are not UTF-8 (``b'\\xff'``) in inputs and outputs of failing commands: one line
          showing the name escaped (``\\udcff``), never a UnicodeEncodeError.
escapes   HDF5 inputs that would read another file: an external link (to an HDF5 file, to a FIFO), external
          storage, a virtual dataset, a FIFO named as the input: refused before anything is followed.
bounds    parameters bounded by memory (n_particles, --dpi, mrclam --dt), seeds >= 2^63, bad mathtext titles,
          deeply nested TOML, inputs of magnitude 1e300.

Every case is judged the same way: exit status != 0 (== ``exit`` when given), no traceback, one ``error:``
line naming ``names``, no ``.tmp-`` entry left under the campaign folder, every watched file byte-identical
(sha256 before and after; "data loss" otherwise), nothing at ``absent``, child peak RSS < 500 MB.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import h5py

HERE = Path(__file__).parent
DATA = HERE.parent / "data"  # tests/data
PEAK_MB = 500.0
#: the child's file-size limit in the RLIMIT_FSIZE family, bytes (every output here is larger)
FSIZE_BYTES = 2048
TMPFS_BYTES = 256 * 1024


@dataclass
class Fault:
    family: str
    id: str
    args: list
    names: str  # substring the error line must contain
    exit: int | None = None  # exact exit status expected; None: any non-zero
    watch: tuple = ()  # files that must be byte-identical afterwards
    absent: Path | None = None  # must not exist afterwards
    fsize: int | None = None
    one_line: bool = True  # a sweep prints its failure table; then only "no traceback" is asked
    env: dict | None = None  # environment variables of the child (a registry, a data folder)
    forbid: str | None = None  # the error line must not contain this (e.g. "--force" for an input)


def sha(p: Path) -> str:
    return hashlib.sha256(Path(p).read_bytes()).hexdigest()


def _alias(p: Path, how: str, links: Path) -> Path:
    """Another name of the existing file ``p``."""
    links.mkdir(exist_ok=True)
    q = links / f"{how}-{p.parent.name}-{p.name}"
    if how == "direct":
        return p
    if how == "symlink":
        if not q.is_symlink():
            q.symlink_to(p)
        return q
    if how == "hardlink":
        if not q.exists():
            os.link(p, q)
        return q
    if how == "dotdot":
        (p.parent / "sub").mkdir(exist_ok=True)
        return p.parent / "sub" / ".." / p.name
    return Path(os.path.relpath(p, links.parent))  # relative to the campaign folder (the cwd)


ALIASES = ("direct", "symlink", "hardlink", "dotdot", "relative")


@dataclass
class World:
    w: Path
    ds: Path
    ds2: Path
    res: Path
    tum: Path
    g2o: Path
    toml: Path
    sweep: Path
    mrclam: Path
    team: Path
    vp: Path
    carpark: Path
    held: list = field(default_factory=list)


def make_world(w: Path) -> World:
    from slamcli.api.interop import export_file
    from slamcli.api.simulate import simulate_to_file
    from slamcli.api.solve import solve_file

    w.mkdir(parents=True, exist_ok=True)
    ds, ds2, res = w / "D.h5", w / "D2.h5", w / "R.h5"
    simulate_to_file("loop", 1, {"n_steps": 120}, ds)
    simulate_to_file("loop", 2, {"n_steps": 120}, ds2)
    solve_file(ds, "odometry", {}, res)
    tum = w / "t.tum"
    export_file(res, "tum", tum)
    g2o = w / "g.g2o"
    shutil.copyfile(DATA / "intel_excerpt.g2o", g2o)
    toml = w / "e.toml"
    toml.write_text('[experiment]\nname = "e"\n[scenario]\nname = "loop"\nparameters = {n_steps = 20}\n'
                    '[[solver]]\nmethod = "odometry"\n')
    sweep = w / "sw"
    sweep.mkdir()
    (sweep / "results.csv").write_text("run_id,label,status\n")
    dirs = {}
    for name, src in (("mrclam", "mrclam_excerpt"), ("team", "mrclam_team_excerpt"), ("vp", "victoria_park_excerpt"),
                      ("carpark", "carpark_excerpt")):
        dirs[name] = w / name
        shutil.copytree(DATA / src, dirs[name])
    return World(w, ds, ds2, res, tum, g2o, toml, sweep, **dirs)


def guard_cases(W: World) -> list[Fault]:
    w, links, out = W.w, W.w / "links", W.w / "out"
    out.mkdir(exist_ok=True)
    cases: list[Fault] = []

    def add(cid, args, names, watch):
        cases.append(Fault("guard", cid, args, names, exit=2, watch=tuple(watch)))

    # the plot kinds read a result by content, not by extension: a result named *.png is a careless-user case
    res_png = w / "R.png"
    shutil.copyfile(W.res, res_png)
    ev = w / "ev"
    ev.mkdir()
    shutil.copyfile(W.res, ev / "R.h5")
    for how in ALIASES:
        A = lambda p: _alias(p, how, links)
        add(f"solve-over-data-{how}", ["solve", W.ds, "-m", "odometry", "-o", A(W.ds), "-q"], "input", [W.ds])
        add(f"solve-over-init-{how}", ["solve", W.ds, "-m", "icm", "--init", W.res, "-o", A(W.res), "-q"], "input",
            [W.res])
        add(f"export-over-result-{how}", ["export", W.res, "-f", "tum", "-o", A(W.res), "-q"], "input", [W.res])
        add(f"export-over-dataset-{how}", ["export", W.ds, "-f", "csv", "-o", A(W.ds), "-q"], "input", [W.ds])
        add(f"export-over-data-{how}", ["export", W.res, "-f", "tum", "--data", W.ds, "-o", A(W.ds), "-q"],
            "input", [W.ds])
        add(f"trajectory-over-tum-{how}", ["import", "trajectory", W.tum, "-d", W.ds, "-o", A(W.tum), "-q"],
            "input", [W.tum])
        add(f"trajectory-over-data-{how}", ["import", "trajectory", W.tum, "-d", W.ds, "-o", A(W.ds), "-q"],
            "input", [W.ds])
        add(f"g2o-over-input-{how}", ["import", "g2o", W.g2o, "-o", A(W.g2o), "-q"], "input", [W.g2o])
        add(f"plot-over-result-{how}", ["plot", "map", res_png, "--data", W.ds, "-o", A(res_png), "-q"], "input",
            [res_png])
    add("evaluate-folder-holds-input", ["evaluate", ev / "R.h5", "--data", W.ds, "-o", ev, "-q"], "contains the input",
        [ev / "R.h5"])
    add("evaluate-folder-dot", ["evaluate", "R.h5", "--data", W.ds, "-o", ".", "-q"], "contains the input", [W.res])
    # files inside an input folder (directly and through a symlinked folder)
    mr_link = links / "mrclam-dir"
    mr_link.symlink_to(W.mrclam)
    for folder, tag in ((W.mrclam, "dir"), (mr_link, "linked-dir")):
        for name in ("Robot1_Odometry.dat", "Robot1_Measurement.dat", "Robot1_Groundtruth.dat", "Barcodes.dat",
                     "Landmark_Groundtruth.dat"):
            add(f"mrclam-{tag}-{name}", ["import", "mrclam", W.mrclam, "-o", folder / name, "-q"], "input folder",
                [W.mrclam / name])
    for name in ("inputs.dat", "measurements.dat", "gps.dat"):
        add(f"vp-{name}", ["import", "victoria-park", W.vp, "-o", W.vp / name, "-q"], "input folder", [W.vp / name])
    for name in ("data_set.mat", "beac_juan3.mat"):
        add(f"carpark-{name}", ["import", "carpark", W.carpark, "-o", W.carpark / name, "-q"], "input folder",
            [W.carpark / name])
    add("mrclam-solo-dir-is-input", ["import", "mrclam", W.team, "--robots", "1,2", "--solo-dir", W.team, "-o",
                                      out / "team.h5", "-q"], "input", [W.team / "Robot1_Odometry.dat"])
    add("reproduce-out-is-experiments-dir", ["reproduce", "--experiments", w / "sw", "--out", w / "sw", "-q"], "input",
        [W.sweep / "results.csv"])
    # special files: the atomic rename would replace them by a regular file
    special = w / "special"
    special.mkdir()
    nodes = {"fifo": special / "fifo"}
    os.mkfifo(nodes["fifo"])
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(special / "sock"))
    W.held.append(sock)
    nodes["socket"] = special / "sock"
    with contextlib.suppress(OSError):  # a character device like /dev/null (needs root)
        os.mknod(special / "null", 0o666 | 0o020000, os.makedev(1, 3))
        nodes["chardev"] = special / "null"
    for kind, node in nodes.items():
        for cid, args in (("simulate", ["simulate", "-s", "loop", "--set", "n_steps=20", "-o", node, "-q"]),
                          ("solve", ["solve", W.ds, "-m", "odometry", "-o", node, "-q"]),
                          ("export", ["export", W.res, "-f", "tum", "-o", node, "-q"]),
                          ("trajectory", ["import", "trajectory", W.tum, "-d", W.ds, "-o", node, "-q"]),
                          ("g2o", ["import", "g2o", W.g2o, "-o", node, "-q"]),
                          ("mrclam", ["import", "mrclam", W.mrclam, "-o", node, "-q"])):
            cases.append(Fault("guard", f"{cid}-to-{kind}", args, "not a regular file", exit=2))
    # a running sweep's results folder (its lock is held by this process for the whole campaign)
    running = w / "running"
    (running / "run1").mkdir(parents=True)
    (running / "results.csv").write_text("run_id,label,status\n")
    fh = open(running / ".sweep.lock", "a+")
    fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    W.held.append(fh)
    for cid, args in (("simulate", ["simulate", "-s", "loop", "--set", "n_steps=20", "-o", running / "d.h5", "-q"]),
                      ("solve", ["solve", W.ds, "-m", "odometry", "-o", running / "run1" / "r.h5", "-q"]),
                      ("evaluate", ["evaluate", W.res, "--data", W.ds, "-o", running / "e", "-q"]),
                      ("export", ["export", W.res, "-f", "tum", "-o", running / "t.tum", "-q"]),
                      ("plot", ["plot", "map", W.res, "--data", W.ds, "-o", running / "m.png", "-q"]),
                      ("aggregate", ["aggregate", running, "-q"]),
                      ("g2o", ["import", "g2o", W.g2o, "-o", running / "g.h5", "-q"])):
        cases.append(Fault("guard", f"{cid}-into-running-sweep", args, "running sweep", exit=2,
                           watch=(running / "results.csv",)))
    # an existing file of another kind (--force would replace it)
    notes = w / "notes.txt"
    notes.write_text("my notes\n")
    for cid, args, target in (("simulate-over-result", ["simulate", "-s", "loop", "-o", W.res, "-q"], W.res),
                              ("solve-over-other-dataset", ["solve", W.ds, "-m", "odometry", "-o", W.ds2, "-q"], W.ds2),
                              ("solve-over-notes", ["solve", W.ds, "-m", "odometry", "-o", notes, "-q"], notes),
                              ("g2o-over-result", ["import", "g2o", W.g2o, "-o", W.res, "-q"], W.res),
                              ("trajectory-over-dataset", ["import", "trajectory", W.tum, "-d", W.ds, "-o", W.ds2,
                                                           "-q"], W.ds2),
                              ("mrclam-over-notes", ["import", "mrclam", W.mrclam, "-o", notes, "-q"], notes)):
        cases.append(Fault("guard", cid, args, "--force", exit=2, watch=(target,)))
    return cases


def _writers(W: World, d: Path, tag: str) -> list[tuple[str, list, Path]]:
    """(id, args, output) of every writing command with its output in folder ``d``."""
    return [
        ("simulate", ["simulate", "-s", "loop", "--set", "n_steps=400", "-o", d / "s.h5", "-q"], d / "s.h5"),
        ("solve-ekf", ["solve", W.ds, "-m", "ekf", "-o", d / "ekf.h5", "-q"], d / "ekf.h5"),
        ("solve-odometry", ["solve", W.ds, "-m", "odometry", "-o", d / "odo.h5", "-q"], d / "odo.h5"),
        ("import-g2o", ["import", "g2o", W.g2o, "-o", d / "g.h5", "-q"], d / "g.h5"),
        ("import-mrclam", ["import", "mrclam", W.mrclam, "-o", d / "m.h5", "-q"], d / "m.h5"),
        ("import-vp", ["import", "victoria-park", W.vp, "-o", d / "vp.h5", "-q"], d / "vp.h5"),
        ("import-carpark", ["import", "carpark", W.carpark, "-o", d / "cp.h5", "-q"], d / "cp.h5"),
        ("import-trajectory", ["import", "trajectory", W.tum, "-d", W.ds, "-o", d / "tr.h5", "-q"], d / "tr.h5"),
        ("export-tum", ["export", W.res, "-f", "tum", "-o", d / "t.tum", "-q"], d / "t.tum"),
        ("export-csv", ["export", W.res, "-f", "csv", "-o", d / "t.csv", "-q"], d / "t.csv"),
        ("export-g2o", ["export", W.res, "-f", "g2o", "-o", d / "t.g2o", "-q"], d / "t.g2o"),
        ("export-kitti", ["export", W.res, "-f", "kitti", "-o", d / "t.kitti", "-q"], d / "t.kitti"),
        ("plot-png", ["plot", "map", W.res, "--data", W.ds, "-o", d / "m.png", "-q"], d / "m.png"),
        ("plot-pdf", ["plot", "map", W.res, "--data", W.ds, "-o", d / "m.pdf", "-q"], d / "m.pdf"),
        ("evaluate", ["evaluate", W.res, "--data", W.ds, "-o", d / "ev", "-q"], d / "ev"),
    ]


def disk_cases(W: World, full: Path | None) -> list[Fault]:
    """The RLIMIT_FSIZE family always; the tmpfs family when ``full`` is a mounted, nearly full tmpfs."""
    cases: list[Fault] = []
    lim = W.w / "fsize"
    lim.mkdir(exist_ok=True)
    for cid, args, target in _writers(W, lim, "fsize"):
        name = target.name if cid != "evaluate" else "ev"
        cases.append(Fault("disk", f"fsize-{cid}", args, name, absent=target, fsize=FSIZE_BYTES))
    if full is None:
        return cases
    old = full / "old.h5"  # an existing output on the full disk: a failed overwrite must leave it whole
    for cid, args, target in _writers(W, full, "tmpfs"):
        name = target.name if cid != "evaluate" else "ev"
        cases.append(Fault("disk", f"tmpfs-{cid}", args, name, absent=target))
    cases.append(Fault("disk", "tmpfs-solve-over-existing", ["solve", W.ds, "-m", "icm", "-o", old, "-q"], "old.h5",
                       watch=(old,)))
    cases.append(Fault("disk", "tmpfs-sweep", ["sweep", W.toml, "--out", full / "sweeps", "-q"], "",
                       one_line=False))
    return cases


def _vp_copy(W: World, cid: str, col: int, value: float) -> Path:
    d = W.w / "imports" / cid
    shutil.copytree(W.vp, d)
    p = d / "measurements.dat"
    lines = p.read_text().splitlines()
    parts = lines[3].split()
    parts[col] = repr(value)
    lines[3] = "  ".join(parts)
    p.write_text("\n".join(lines) + "\n")
    return d


def import_cases(W: World) -> list[Fault]:
    out = W.w / "out"
    cases: list[Fault] = []
    for cid, col, v in (("bearing-10rad", 2, 10.0), ("bearing-minus-10rad", 2, -10.0), ("bearing-3.2rad", 2, 3.2),
                        ("bearing-minus-0.01", 2, -0.01), ("range-zero", 1, 0.0), ("range-negative", 1, -1.0),
                        ("diameter-negative", 3, -0.3)):
        d = _vp_copy(W, cid, col, v)
        t = out / f"vp-{cid}.h5"
        field_name = {1: "range", 2: "bearing", 3: "diameter"}[col]
        cases.append(Fault("import", f"vp-{cid}", ["import", "victoria-park", d, "-o", t, "-q"],
                           f"measurements.dat: line 4: {field_name}", absent=t, watch=(d / "measurements.dat",)))
    for v in ("-1", "0", "nan", "-inf"):
        t = out / f"cp-{v}.h5"
        cases.append(Fault("import", f"carpark-max-range-{v}", ["import", "carpark", W.carpark, "--max-range", v,
                                                                  "-o", t, "-q"], "--max-range", absent=t))
    for v in ("1e-9", "1e-7", "0", "-1", "nan", "inf"):
        t = out / f"mr-{v}.h5"
        cases.append(Fault("import", f"mrclam-dt-{v}", ["import", "mrclam", W.mrclam, "--dt", v, "-o", t, "-q"],
                           "--dt", absent=t))
    t = out / "mr-team-dt.h5"
    cases.append(Fault("import", "mrclam-team-dt-1e-9", ["import", "mrclam", W.team, "--robots", "1,2", "--dt", "1e-9",
                                                         "-o", t, "-q"], "--dt", absent=t))
    t = out / "mr-std-dt.h5"
    cases.append(Fault("import", "mrclam-dt-1e-9-with-noise", ["import", "mrclam", W.mrclam, "--dt", "1e-9",
                                                               "--range-std", "0.1", "-o", t, "-q"], "--dt", absent=t))
    return cases


def _edit(W: World, cid: str, name: str, fn) -> Path:
    p = W.w / "bounds" / f"{cid}.h5"
    p.parent.mkdir(exist_ok=True)
    shutil.copyfile(W.ds, p)
    with h5py.File(p, "r+") as f:
        a = f[name][...]
        fn(a)
        del f[name]
        f.create_dataset(name, data=a)
    return p


def bounds_cases(W: World) -> list[Fault]:
    out = W.w / "out"
    cases: list[Fault] = []

    def add(cid, args, names, target):
        cases.append(Fault("bounds", cid, args, names, absent=target))

    for v in ("1e8", "1e12", "100000000", str(2**63)):
        t = out / f"np-{v}.h5"
        add(f"n_particles-{v}", ["solve", W.ds, "-m", "fastslam", "-p", f"n_particles={v}", "-o", t, "-q"],
            "n_particles", t)
    for cmd in ("simulate", "solve"):
        for v in (str(2**63), str(2**70), "-1"):
            t = out / f"seed-{cmd}-{v}.h5"
            head = ["simulate", "-s", "loop"] if cmd == "simulate" else ["solve", W.ds, "-m", "odometry"]
            add(f"seed-{cmd}-{v}", [*head, "--seed", v, "-o", t, "-q"], "--seed", t)
    for v in ("100000", "70000", "9000", "0", "-5"):
        t = out / f"dpi-{v}.png"
        add(f"plot-dpi-{v}", ["plot", "map", W.res, "--data", W.ds, "--dpi", v, "-o", t, "-q"], "--dpi", t)
    for i, title in enumerate(("$x^$", r"$\frac{1}$", r"$\sqrt{$", "$a_$", r"$\left($")):
        t = out / f"title-{i}.png"
        add(f"plot-title-mathtext-{i}", ["plot", "map", W.res, "--data", W.ds, "--title", title, "-o", t, "-q"],
            "--title", t)
    base = W.toml.read_text()
    for cid, extra in (("arrays-1e5", "[extra]\nv = " + "[" * 100000 + "]" * 100000 + "\n"),
                       ("arrays-100", "[extra]\nv = " + "[" * 100 + "]" * 100 + "\n"),
                       ("inline-tables-1e4", "[extra]\nv = " + "{a = " * 10000 + "1" + "}" * 10000 + "\n")):
        p = W.w / "bounds" / f"{cid}.toml"
        p.parent.mkdir(exist_ok=True)
        p.write_text(base + extra)
        add(f"toml-nested-{cid}", ["sweep", p, "--out", out / f"sw-{cid}", "--dry-run", "-q"], p.name, None)
    for cid, name, fn in (("odometry-1e300", "inputs/odometry_xyt", lambda a: a.__setitem__((slice(5, None), 0), 1e300)),
                          ("odometry-minus-1e300", "inputs/odometry_xyt", lambda a: a.__setitem__((7, 1), -1e300)),
                          ("controls-1e300", "inputs/controls", lambda a: a.__setitem__((3, 0), 1e300)),
                          ("x0-1e300", "inputs/x0", lambda a: a.__setitem__(0, 1e300))):
        p = _edit(W, cid, name, fn)
        for method in ("icm", "ekf", "graph", "odometry"):
            t = out / f"{cid}-{method}.h5"
            cases.append(Fault("bounds", f"{cid}-{method}", ["solve", p, "-m", method, "-o", t, "-q"], name,
                               absent=t, watch=(p,)))
    return cases


def _registry_env(W: World) -> tuple[dict, dict[str, Path]]:
    """A local registry (a g2o, an MRCLAM and a Victoria Park recording) whose copies are registered as added
    folders of a data folder: the child's environment and name → folder."""
    root = W.w / "registered"
    folders = {"graph-t": root / "graphs", "mr-t": root / "mrclam", "vp-t": root / "vp"}
    if not root.exists():
        folders["graph-t"].mkdir(parents=True)
        shutil.copyfile(W.g2o, folders["graph-t"] / "intel.g2o")
        shutil.copytree(W.mrclam, folders["mr-t"])
        shutil.copytree(W.vp, folders["vp-t"])
        (root / "data").mkdir()
        (root / "data" / "registered.json").write_text(json.dumps({k: str(v) for k, v in folders.items()}))
        (root / "registry.toml").write_text("".join(
            f'[[dataset]]\nname = "{n}"\nimporter = "{imp}"\nmarker = "{m}"\nfolder = "{n}"\n'
            for n, imp, m in (("graph-t", "g2o", "intel.g2o"), ("mr-t", "mrclam", "Barcodes.dat"),
                              ("vp-t", "victoria-park", "inputs.dat"))))
    env = {"SLAMCLI_DATA_DIR": str(root / "data"), "SLAMCLI_DATASET_REGISTRY": str(root / "registry.toml")}
    return env, folders


def implicit_cases(W: World) -> list[Fault]:
    from slamcli.api.simulate import simulate_to_file
    from slamcli.api.solve import solve_file

    d, links = W.w / "implicit", W.w / "links"
    d.mkdir()
    cases: list[Fault] = []
    for how in ("direct", "symlink", "hardlink", "relative"):
        target = _alias(W.ds, how, links)
        for fmt in ("tum", "kitti", "csv", "g2o", "gtsam"):
            cases.append(Fault("implicit", f"export-{fmt}-over-recorded-dataset-{how}",
                               ["export", W.res, "-f", fmt, "-o", target, "-q"], "input", exit=2, watch=(W.ds,)))
    dpng = d / "dataset.png"  # a dataset with an image's name: what plot map/errors would write over
    simulate_to_file("loop", 4, {"n_steps": 40}, dpng)
    rpng = d / "on-png.h5"
    solve_file(dpng, "odometry", {}, rpng)
    for kind in ("map", "errors"):
        cases.append(Fault("implicit", f"plot-{kind}-over-recorded-dataset", ["plot", kind, rpng, "-o", dpng, "-q"],
                           "input", exit=2, watch=(dpng,)))
    inner = d / "inner"
    inner.mkdir()
    dsin = inner / "d.h5"
    shutil.copyfile(W.ds, dsin)
    rin = d / "r-inner.h5"
    solve_file(dsin, "odometry", {}, rin)
    cases.append(Fault("implicit", "evaluate-folder-holds-recorded-dataset", ["evaluate", rin, "-o", inner, "-q"],
                       "contains the input", exit=2, watch=(dsin,)))
    user = d / "ev-user" / "per_step.csv"  # a user folder whose entries carry evaluate's output names
    user.mkdir(parents=True)
    (user / "thesis.tex").write_text("\\chapter{x}\n")
    cases.append(Fault("implicit", "evaluate-user-folder-named-like-outputs",
                       ["evaluate", W.res, "-o", user.parent, "-q"], "per_step.csv", watch=(user / "thesis.tex",)))
    env, reg = _registry_env(W)
    for cid, args, target in (
            ("g2o-by-name", ["import", "g2o", "graph-t", "-o", reg["graph-t"] / "intel.g2o"], reg["graph-t"] / "intel.g2o"),
            ("mrclam-by-name", ["import", "mrclam", "mr-t", "-o", reg["mr-t"] / "Barcodes.dat"],
             reg["mr-t"] / "Barcodes.dat"),
            ("vp-by-name", ["import", "victoria-park", "vp-t", "-o", reg["vp-t"] / "gps.dat"], reg["vp-t"] / "gps.dat"),
            ("g2o-other-file", ["import", "g2o", W.g2o, "-o", reg["mr-t"] / "Robot1_Odometry.dat"],
             reg["mr-t"] / "Robot1_Odometry.dat"),
            ("simulate", ["simulate", "-s", "loop", "--set", "n_steps=20", "-o", reg["vp-t"] / "inputs.dat"],
             reg["vp-t"] / "inputs.dat"),
            ("solve", ["solve", W.ds, "-m", "odometry", "-o", reg["graph-t"] / "intel.g2o"], reg["graph-t"] / "intel.g2o")):
        for force in ((), ("--force",)):
            cases.append(Fault("implicit", f"registered-{cid}{'-force' if force else ''}", [*args, *force, "-q"],
                               "input", exit=2, watch=(target,), env=env, forbid="--force"))
    cases.append(Fault("implicit", "registered-export", ["export", W.res, "-f", "tum", "-o",
                                                         reg["mr-t"] / "Robot1_Measurement.dat", "-q"],
                       "input folder", exit=2, watch=(reg["mr-t"] / "Robot1_Measurement.dat",), env=env))
    solo = d / "solo"
    solo.mkdir()
    shutil.copyfile(W.ds2, solo / "robot1.h5")  # the user's own file of that name
    cases.append(Fault("implicit", "mrclam-solo-dir-existing", ["import", "mrclam", W.team, "--robots", "1,2",
                                                                "--solo-dir", solo, "-o", d / "team.h5", "-q"],
                       "robot1.h5", exit=2, watch=(solo / "robot1.h5",), absent=d / "team.h5"))
    return cases


def _text_copy(W: World, src: Path, cid: str, edit) -> Path:
    """A copy of the file or folder ``src`` under ``wrong/cid``; ``edit(path)`` changes the copy."""
    d = W.w / "wrong" / cid
    d.parent.mkdir(exist_ok=True)
    if src.is_dir():
        shutil.copytree(src, d)
    else:
        d.mkdir()
        shutil.copyfile(src, d / src.name)
    edit(d if src.is_dir() else d / src.name)
    return d if src.is_dir() else d / src.name


def _set_field(path: Path, row: int, col: int, value: str) -> None:
    """Set whitespace-separated field ``col`` of data row ``row`` (comments skipped) of a text file."""
    lines = path.read_text().splitlines()
    rows = [i for i, s in enumerate(lines) if s.strip() and not s.lstrip().startswith("#")]
    parts = lines[rows[row]].split()
    parts[col] = value
    lines[rows[row]] = " ".join(parts)
    path.write_text("\n".join(lines) + "\n")


def _mat_edit(**changes):
    """An edit of a car-park folder: variables of its data_set.mat replaced (scipy.io, compressed)."""

    def edit(d: Path) -> None:
        import scipy.io as sio

        m = {k: v for k, v in sio.loadmat(d / "data_set.mat").items() if not k.startswith("__")}
        m.update({k: (f(m[k]) if callable(f) else f) for k, f in changes.items()})
        sio.savemat(d / "data_set.mat", m, do_compression=True)

    return edit


def wrong_cases(W: World) -> list[Fault]:
    import numpy as np

    out = W.w / "out"
    cases: list[Fault] = []

    def add(cid, args, names, watch=()):
        t = out / f"wrong-{cid}.h5"
        cases.append(Fault("wrong", cid, [*args, "-o", t, "-q"], names, absent=t, watch=tuple(watch)))

    g = lambda cid, edit: _text_copy(W, W.g2o, cid, edit)
    add("g2o-dx-1e300", ["import", "g2o", g("g2o-dx", lambda p: _set_field(p, 0, 3, "1e300"))], "g2o-dx")
    add("g2o-dt-1e-320", ["import", "g2o", W.g2o, "--dt", "1e-320"], "wrong-g2o-dt-1e-320.h5")
    for sigma in ("1e-200", "1e200"):
        br = g(f"g2o-br-{sigma}", lambda p, s=sigma: p.write_text(p.read_text() + f"BR 1 9000 0.3 2.0 {s} 0.1\n"))
        add(f"g2o-br-sigma-{sigma}", ["import", "g2o", br], "positive definite")
    mr = _text_copy(W, W.mrclam, "mrclam-v", lambda d: _set_field(d / "Robot1_Odometry.dat", 15, 1, "1e300"))
    add("mrclam-v-1e300", ["import", "mrclam", mr], "wrong-mrclam-v-1e300.h5")
    vp = _text_copy(W, W.vp, "vp-speed", lambda d: _set_field(d / "inputs.dat", 4, 1, "1e300"))
    add("vp-speed-1e300", ["import", "victoria-park", vp], "wrong-vp-speed-1e300.h5")
    vp = _text_copy(W, W.vp, "vp-gps-back", lambda d: _set_field(d / "gps.dat", 2, 0, "0.5"))
    add("vp-gps-time-backwards", ["import", "victoria-park", vp], "gps.dat: row 3")
    for cid, edit, names in (
            ("velocity-1e300", _mat_edit(Velocity=lambda a: np.where(np.arange(a.size).reshape(a.shape) == 7, 1e300, a)),
             "wrong-carpark-velocity-1e300.h5"),
            ("laser-strings", _mat_edit(Laser=lambda a: np.full(a.shape, "ab", dtype="<U2")), "'Laser'"),
            ("mat-bomb", _mat_edit(Index=np.zeros((1, 100_000_000), np.uint8)), "inflated")):  # ~100 kB on disk
        add(f"carpark-{cid}", ["import", "carpark", _text_copy(W, W.carpark, f"cp-{cid}", edit)], names)
    for cid, setting, names in (("dt-1e300", "dt=1e300", "dt"), ("start-1e300", "robot.start=[1e300,0,0]",
                                                                      "robot.start")):
        add(f"simulate-{cid}", ["simulate", "-s", "loop", "--set", setting], names)
    for cid, opt in (("cutoff-1e300", ["--cutoff", "1e300"]), ("cutoff-1e-300", ["--cutoff", "1e-300"]),
                     ("rpe-delta-1e300", ["--rpe-delta", "1e300"])):
        t = out / f"wrong-ev-{cid}"
        cases.append(Fault("wrong", f"evaluate-{cid}", ["evaluate", W.res, *opt, "-o", t, "-q"], cid.split("-")[0],
                           absent=t))
    t = out / "wrong-ellipse.png"
    cases.append(Fault("wrong", "plot-pose-ellipse-every-minus-1", ["plot", "map", W.res, "--ellipses",
                                                                    "--pose-ellipse-every", "-1", "-o", t, "-q"],
                       "--pose-ellipse-every", absent=t))
    loop = W.w / "wrong" / "loop-a"
    loop.symlink_to("loop-b")
    (W.w / "wrong" / "loop-b").symlink_to("loop-a")
    for cid, args in (("solve", ["solve", W.ds, "-m", "odometry", "-o", loop]),
                      ("solve-inside", ["solve", W.ds, "-m", "odometry", "-o", loop / "r.h5"]),
                      ("simulate-force", ["simulate", "-s", "loop", "--force", "-o", loop]),
                      ("export", ["export", W.res, "-f", "tum", "-o", loop]),
                      ("evaluate", ["evaluate", W.res, "-o", loop]),
                      ("plot", ["plot", "map", W.res, "-o", loop / "m.png"]),
                      ("sweep", ["sweep", W.toml, "--out", loop / "s"])):
        cases.append(Fault("wrong", f"symlink-loop-{cid}", [*args, "-q"], "loop of symbolic links"))
    return cases


def registry_cases(W: World) -> list[Fault]:
    d = W.w / "hostile"
    d.mkdir()
    cases: list[Fault] = []
    base = {"name": "evil", "importer": "victoria-park", "marker": "inputs.dat", "folder": "evil"}
    for cid, field_name, value in (("marker-dotdot", "marker", "../../../../../../etc/passwd"),
                                   ("marker-absolute", "marker", "/etc/passwd"),
                                   ("folder-dotdot", "folder", ".."), ("folder-absolute", "folder", "/etc"),
                                   ("folder-nested", "folder", "a/../../b"), ("name-escape", "name", "e\\u001b[2J")):
        toml = d / f"{cid}.toml"
        toml.write_text("[[dataset]]\n" + "".join(f'{k} = "{v}"\n' for k, v in {**base, field_name: value}.items()))
        env = {"SLAMCLI_DATASET_REGISTRY": str(toml), "SLAMCLI_DATA_DIR": str(d / "data"), "SLAMCLI_DATASETS": "/"}
        t = d / f"{cid}.h5"
        for sub, args in (("path", ["datasets", "path", "evil"]),
                          ("import", ["import", "victoria-park", "evil", "-o", t, "-q"])):
            cases.append(Fault("registry", f"{cid}-{sub}", args, field_name, env=env, absent=t, forbid="\x1b"))
    deep = "[" * 100_000 + "]" * 100_000
    (d / "deep.toml").write_text(f'[[dataset]]\nname = "x"\nv = {deep}\n')
    (d / "deepdata").mkdir()
    (d / "deepdata" / "registered.json").write_text(deep)
    for cid, env, names in (("deep-toml", {"SLAMCLI_DATASET_REGISTRY": str(d / "deep.toml")}, "deep.toml"),
                            ("deep-registered-json", {"SLAMCLI_DATA_DIR": str(d / "deepdata")}, "registered.json")):
        cases.append(Fault("registry", cid, ["datasets", "list"], names, env=env))
    return cases


def name_cases(W: World) -> list[Fault]:
    d = W.w / "names"
    d.mkdir()
    bad = lambda s: d / os.fsdecode(s.encode() + b"\xff")
    text = bad("notes.h5")
    text.write_text("not hdf5\n")
    g2o = bad("graph.g2o")
    g2o.write_text(W.g2o.read_text() + "EDGE_SE2 1 1 0 0 0 1 0 0 1 0 1\n")
    link = bad("D.h5")
    os.link(W.ds, link)
    folder_file = bad("sw")
    folder_file.write_text("x")
    cases = [Fault("names", "info-missing", ["info", bad("missing.h5")], "missing.h5\\udcff"),
             Fault("names", "solve-not-hdf5", ["solve", text, "-m", "odometry", "-o", d / "r.h5", "-q"],
                   "notes.h5\\udcff: not an HDF5 file", absent=d / "r.h5"),
             Fault("names", "g2o-bad-line", ["import", "g2o", g2o, "-o", bad("g.h5"), "-q"], "graph.g2o\\udcff:",
                   absent=bad("g.h5")),
             Fault("names", "export-over-linked-dataset", ["export", W.res, "-f", "tum", "-o", link, "-q"], "input",
                   exit=2, watch=(W.ds,)),
             Fault("names", "sweep-out-is-a-file", ["sweep", W.toml, "--out", folder_file, "-q"], "sw\\udcff"),
             Fault("names", "evaluate-into-bad-name", ["evaluate", text, "-o", bad("ev"), "-q"], "notes.h5\\udcff",
                   absent=bad("ev"))]
    return cases


def _escaping_copy(W: World, src: Path, cid: str, name: str, how: str) -> Path:
    """A copy of ``src`` whose dataset ``name`` reads another file (``how``: ``link``, ``fifo-link``,
    ``virtual``, ``external``); the other files sit beside it and hold valid data."""
    d = W.w / "escapes"
    d.mkdir(exist_ok=True)
    p = d / f"{cid}.h5"
    shutil.copyfile(src, p)
    with h5py.File(p, "r+") as f:
        data = f[name][()]
        side = d / f"{cid}-side.h5"
        with h5py.File(side, "w") as g:
            g["v"] = data
        del f[name]
        if how == "link":
            f[name] = h5py.ExternalLink(side.name, "v")
        elif how == "fifo-link":
            os.mkfifo(d / f"{cid}.fifo")
            f[name] = h5py.ExternalLink(f"{cid}.fifo", "v")
        elif how == "virtual":
            layout = h5py.VirtualLayout(shape=data.shape, dtype=data.dtype)
            layout[...] = h5py.VirtualSource(side.name, "v", shape=data.shape)
            f.create_virtual_dataset(name, layout)
        else:
            raw = d / f"{cid}.raw"
            raw.write_bytes(data.tobytes())
            f.create_dataset(name, shape=data.shape, dtype=data.dtype, external=[(raw.name, 0, data.nbytes)])
    return p


def escape_cases(W: World) -> list[Fault]:
    out = W.w / "out"
    cases: list[Fault] = []
    for how in ("link", "fifo-link", "virtual", "external"):
        p = _escaping_copy(W, W.ds, f"ds-{how}", "inputs/x0", how)
        r = _escaping_copy(W, W.res, f"res-{how}", "poses_xyt", how)
        for cid, args, target in (
                ("solve", ["solve", p, "-m", "odometry", "-o", out / f"e-{how}.h5", "-q"], out / f"e-{how}.h5"),
                ("info", ["info", p], None),
                ("export-data", ["export", W.res, "-f", "tum", "--data", p, "-o", out / f"e-{how}.tum", "-q"],
                 out / f"e-{how}.tum"),
                ("evaluate-data", ["evaluate", W.res, "--data", p, "-o", out / f"ev-{how}", "-q"], out / f"ev-{how}"),
                ("export-result", ["export", r, "-f", "tum", "-o", out / f"r-{how}.tum", "-q"], out / f"r-{how}.tum"),
                ("info-result", ["info", r], None),
                ("diff", ["diff", W.res, r], None)):
            names = f"{'inputs/x0' if 'result' not in cid and cid != 'diff' else 'poses_xyt'}"
            cases.append(Fault("escapes", f"{cid}-{how}", args, names, absent=target, watch=(p, r)))
    fifo = W.w / "escapes" / "named.fifo"
    os.mkfifo(fifo)
    for cid, args in (("solve", ["solve", fifo, "-m", "odometry", "-o", out / "fifo.h5", "-q"]), ("info", ["info", fifo]),
                      ("export", ["export", fifo, "-f", "tum", "-o", out / "fifo.tum", "-q"])):
        cases.append(Fault("escapes", f"{cid}-named-fifo", args, "not a regular file"))
    return cases


@contextlib.contextmanager
def full_tmpfs(path: Path):
    """A 256 kB tmpfs at ``path`` with an existing dataset ``old.h5`` and a filler leaving ~4 kB free; yields
    None when mounting is not possible here (not root, no CAP_SYS_ADMIN)."""
    path.mkdir(parents=True, exist_ok=True)
    ok = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={TMPFS_BYTES}", "tmpfs", str(path)],
                        capture_output=True).returncode == 0
    if not ok:
        yield None
        return
    try:
        from slamcli.api.simulate import simulate_to_file

        simulate_to_file("loop", 3, {"n_steps": 20}, path / "old.h5")
        free = shutil.disk_usage(path).free
        (path / "filler").write_bytes(b"\0" * max(free - 4096, 0))
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


def judge(c: Fault, r: dict, before: dict[Path, str], w: Path) -> tuple[str, list[str]]:
    """('clean' | 'traceback' | 'loss' | 'unclear', reasons) for one finished case."""
    why, kind = [], "clean"
    err = r["stderr"]
    lines = err.strip().splitlines()
    if "Traceback" in err or r["code"] not in range(1, 128):
        kind = "traceback"
        why.append(f"exit {r['code']}" + (", traceback" if "Traceback" in err else ""))
    elif c.exit is not None and r["code"] != c.exit:
        why.append(f"exit {r['code']}, expected {c.exit}")
    if c.one_line and (len(lines) != 1 or not lines[0].startswith("error: ") or c.names not in lines[0]):
        why.append(f"not one error line naming {c.names!r}")
    if c.forbid is not None and c.forbid in err:
        why.append(f"the error suggests {c.forbid!r}")
    lost = [str(p) for p, h in before.items() if not p.exists() or sha(p) != h]
    if c.absent is not None and os.path.lexists(c.absent):
        lost.append(f"{c.absent} exists")
    temps = [str(p) for p in w.rglob("*") if ".tmp-" in p.name]
    if lost or temps:
        kind = "loss"
        why += [f"changed/left: {', '.join(lost + temps)[:200]}"]
        for p in temps:  # so that one leftover is not blamed on every later case
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
    if r["maxrss_mb"] >= PEAK_MB:
        why.append(f"peak RSS {r['maxrss_mb']:.0f} MB")
    if why and kind == "clean":
        kind = "unclear"
    return kind, why


def run_campaign(w: Path, only: tuple[str, ...] = ()) -> dict:
    """Build every case under ``w`` (``only``: of these families), run them, return totals and the problems
    (one line each)."""
    from test_bad_input_helpers import CliServer

    W = make_world(w / "world")
    totals = {"cases": 0, "clean": 0, "traceback": 0, "loss": 0, "unclear": 0, "peak_mb": 0.0}
    problems: list[str] = []
    families: dict[str, int] = {}
    times: list[tuple[float, str]] = []
    server = CliServer(w)
    try:
        with full_tmpfs(W.w / "full") as full:
            cases = (guard_cases(W) + disk_cases(W, full) + import_cases(W) + implicit_cases(W) + wrong_cases(W)
                     + name_cases(W) + registry_cases(W) + escape_cases(W)
                     + bounds_cases(W))
            totals["tmpfs"] = full is not None
            for c in (c for c in cases if not only or c.family in only):
                watch = {Path(p): sha(p) for p in (*c.watch, W.ds, W.res, W.tum, W.g2o)}
                t0 = time.perf_counter()
                r = server.run(c.args, W.w, fsize=c.fsize, env=c.env)
                times.append((time.perf_counter() - t0, f"{c.family}/{c.id}"))
                kind, why = judge(c, r, watch, W.w)
                totals["cases"] += 1
                totals[kind] += 1
                families[c.family] = families.get(c.family, 0) + 1
                totals["peak_mb"] = max(totals["peak_mb"], r["maxrss_mb"])
                if why:
                    problems.append(f"{c.family}/{c.id}: {'; '.join(why)}: {r['stderr'].strip()[-240:]!r}")
    finally:
        server.close()
        for h in W.held:
            h.close()
    totals["families"] = families
    totals["slowest"] = sorted(times, reverse=True)[:8]
    totals["wall_s"] = sum(t for t, _ in times)
    totals["problems"] = problems
    return totals


def report(t: dict) -> str:
    fam = ", ".join(f"{k} {v}" for k, v in t["families"].items())
    return (f"cases {t['cases']} ({fam}; tmpfs {'mounted' if t['tmpfs'] else 'not available'}), clean errors "
            f"{t['clean']}, tracebacks {t['traceback']}, data loss {t['loss']}, other problems {t['unclear']}, "
            f"peak RSS {t['peak_mb']:.0f} MB")


if __name__ == "__main__":  # pragma: no cover - see benchmarks/faults.py
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        res = run_campaign(Path(d), tuple(sys.argv[1:]))
    print(report(res))
    print(f"  wall {res['wall_s']:.1f} s; slowest: " + ", ".join(f"{n} {t:.1f} s" for t, n in res["slowest"]))
    for line in res["problems"]:
        print(" ", line)
    sys.exit(1 if res["problems"] else 0)
