"""``slamcli import <format>``: turn a public real-world recording into a slamcli dataset file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import click
import typer

from slamcli.cli.app import SlamcliTyper, app, check_output, choice, fail, handle_errors, stdout_console

_Force = Annotated[bool, typer.Option("--force", help="Replace an existing -o that is not a slamcli dataset (mrclam "
                                                     "--solo-dir: replace existing robotN.h5).")]
_Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No summary line.")]
_Out = Annotated[Path | None, typer.Option("-o", "--out", help="Dataset file to write (HDF5, atomically).")]

import_app = SlamcliTyper(
    help="Import a recording, a landmark graph or another estimator's trajectory: then solve/evaluate/plot work on it.",
    no_args_is_help=True,
)
app.add_typer(import_app, name="import")


def _import_mrclam_team(directory: Path, robots: str | None, all_robots: bool, solo_dir: Path | None, out: Path,
                        quiet: bool, *, no_truth: bool, non_landmark: str, force: bool, **kw) -> None:
    """``import mrclam --robots`` / ``--all-robots``: one multi-robot dataset."""
    import os

    from slamcli.datasets.mrclam import import_mrclam_team
    from slamcli.datasets.options import robot_numbers
    from slamcli.datasets.team import solo_dataset
    from slamcli.io import write_dataset
    from slamcli.io.guard import OutputRefused

    if robots is not None and all_robots:
        fail("--robots and --all-robots: give one of them")
    if no_truth:
        fail("--no-truth: a multi-robot import needs the motion-capture start poses (one world frame for all robots)")
    if non_landmark != "drop":
        fail("--non-landmark: with --robots, robot rows become inter-robot readings; only 'drop' applies")
    try:
        listed = None if all_robots else [int(x) for x in robots.split(",") if x.strip()]
    except ValueError:
        fail(f"--robots: expected comma-separated robot numbers like 1,2,3, got {robots!r}")
    numbers = robot_numbers(directory, listed, all_robots)
    if solo_dir is not None:
        check_output(solo_dir, folder=True, option="--solo-dir", inputs=[directory, out])
        for n in numbers:  # each solo file: guarded like -o, and an existing one is replaced only with --force
            solo = solo_dir / f"robot{n}.h5"
            check_output(solo, option="--solo-dir", inputs=[directory, out], kind="dataset", force=force)
            if os.path.lexists(solo) and not force:
                raise OutputRefused(f"--solo-dir {solo_dir}: {solo.name} exists; --force replaces it")
    ds = import_mrclam_team(directory, numbers, **kw)
    write_dataset(out, ds)
    written = [out]
    if solo_dir is not None:
        solo_dir.mkdir(parents=True, exist_ok=True)
        for r, n in enumerate(ds.inputs.robots.robot_number):
            written.append(write_dataset(solo_dir / f"robot{int(n)}.h5", solo_dataset(ds, r)))
    if quiet:
        return
    inp, rr = ds.inputs, ds.metadata["robot_rows"]
    T = inp.n_poses // len(numbers) - 1
    stdout_console().print(
        f"MRCLAM {Path(directory).name} robots {','.join(map(str, numbers))}: {T} steps each ({T * inp.dt:.1f} s, "
        f"dt {inp.dt:g} s), {len(inp.observations)} landmark observations, {rr['kept']} inter-robot readings of "
        f"{rr['n_rows_with_robot_barcode']} rows with a robot's barcode ({rr['dropped_outside_time_base']} outside "
        f"the common time base, {rr['dropped_robot_not_imported']} of robots not imported)"
        f"{_repairs_phrase({k: v for pr in ds.metadata['per_robot'] for k, v in pr['stamp_repairs'].items()})} → "
        f"{', '.join(map(str, written))}",
        highlight=False, markup=False, soft_wrap=True)


@import_app.command("mrclam")
def import_mrclam_command(
    directory: Annotated[
        Path, typer.Argument(help="MRCLAM dataset folder (Barcodes.dat, RobotN_*.dat, ...) or a dataset name "
                             "(mrclam1..mrclam9, see `slamcli datasets list`).")
    ],
    robot: Annotated[int, typer.Option("--robot", "-r", help="Robot number N (RobotN_*.dat).")] = 1,
    dt: Annotated[float, typer.Option(help="Sampling period of the dataset, s.")] = 0.1,
    start: Annotated[
        float, typer.Option(help="Start, s after the first moment with both odometry and ground truth.")
    ] = 0.0,
    duration: Annotated[float | None, typer.Option(help="Window length, s (default: to the end).")] = None,
    non_landmark: Annotated[
        choice("NonLandmark", ("drop", "clutter")),
        typer.Option(
            help="Rows that see another robot or an unknown barcode: drop, or clutter (reported_id -1)."
        ),
    ] = "drop",
    control_delay: Annotated[
        float,
        typer.Option(
            help="Seconds added to the odometry stamps (Dataset 7 truth lags the log by ~0.15-0.2 s)."
        ),
    ] = 0.0,
    max_range: Annotated[
        float,
        typer.Option(help="Sensor max range to store, m (default inf; Dataset 7 ranges reach 7.2-8.4 m)."),
    ] = float("inf"),
    range_std: Annotated[float | None, typer.Option(help="σ_r to store, m (default 0.15).")] = None,
    bearing_std: Annotated[float | None, typer.Option(help="σ_b to store, rad (default 0.02).")] = None,
    v_std: Annotated[
        float | None, typer.Option(help="σ_v of the controls to store, m/s (default 0.015).")
    ] = None,
    omega_std: Annotated[
        float | None, typer.Option(help="σ_ω of the controls to store, rad/s (default 0.07).")
    ] = None,
    no_truth: Annotated[bool, typer.Option(
        "--no-truth", help="Copy without Groundtruth files: x0 = 0 (own frame), no ground truth stored.")] = False,
    robots: Annotated[str | None, typer.Option(
        "--robots", help="Several robots into ONE multi-robot dataset, e.g. 1,2,3,4,5 (one time base, shared "
                         "landmarks, inter-robot readings); replaces --robot.")] = None,
    all_robots: Annotated[bool, typer.Option(
        "--all-robots", help="Same as --robots with every RobotN_Odometry.dat in the folder.")] = False,
    solo_dir: Annotated[Path | None, typer.Option(
        "--solo-dir", help="With --robots: also write each robot alone on the same time grid, robotN.h5 in this "
                           "folder (to compare solo and joint solves).")] = None,
    quiet: _Quiet = False,
    out: _Out = None,
    force: _Force = False,
) -> None:
    """Import robot --robot of a UTIAS MRCLAM dataset: controls resampled to --dt, barcode ids as reported ids,
    motion-capture ground truth for evaluation. --robots / --all-robots: one multi-robot dataset."""
    with handle_errors():
        if out is None:
            fail("-o/--out is required")
        from slamcli.datasets.mrclam import import_mrclam, noise_from_options
        from slamcli.datasets.registry import resolve_source
        from slamcli.io import write_dataset

        directory = resolve_source(directory, "mrclam")  # (first: a registered name's folder is the input)
        check_output(out, inputs=[directory], kind="dataset", force=force)
        non_landmark = str(non_landmark)
        noise = noise_from_options(dt, range_std, bearing_std, v_std, omega_std)
        if robots is not None or all_robots:
            _import_mrclam_team(directory, robots, all_robots, solo_dir, out, quiet, dt=dt, start=start,
                                duration=duration, noise=noise, control_delay=control_delay, max_range=max_range,
                                no_truth=no_truth, non_landmark=non_landmark, force=force)
            return
        if solo_dir is not None:
            fail("--solo-dir: only with --robots or --all-robots")
        ds = import_mrclam(
            directory,
            robot,
            dt=dt,
            start=start,
            duration=duration,
            non_landmark=non_landmark,
            noise=noise,
            control_delay=control_delay,
            max_range=max_range,
            no_truth=no_truth,
        )
        write_dataset(out, ds)
        if not quiet:
            stdout_console().print(f"{_mrclam_summary(ds, directory, robot, non_landmark)} → {out}",
                                   highlight=False, markup=False, soft_wrap=True)


def _mrclam_summary(ds, directory: Path, robot: int, non_landmark: str) -> str:
    """The one summary line of a single-robot MRCLAM import."""
    import numpy as np

    inp, md = ds.inputs, ds.metadata
    T = inp.n_poses - 1
    if ds.truth is None:
        return (f"MRCLAM {directory.name} robot {robot} (no ground truth): {T} steps of {inp.dt:g} s, "
                f"{len(inp.observations)} observations, odometry path "
                f"{float(np.sum(np.hypot(*np.diff(inp.odometry_xyt[:, :2], axis=0).T))):.1f} m"
                f"{_repairs_phrase(md['stamp_repairs'])}")
    path_len = float(np.sum(np.hypot(*np.diff(ds.truth.poses_xyt[:, :2], axis=0).T)))
    n_clutter = int(np.sum(inp.observations.reported_id < 0))
    return (f"MRCLAM {directory.name} robot {robot}: {T} steps ({T * inp.dt:.1f} s from {inp.timestamps[0]:g} s, "
            f"dt {inp.dt:g} s), {len(ds.truth.landmarks_xy)} landmarks, {len(inp.observations)} observations "
            f"({n_clutter} clutter; {md['n_robot_rows_in_window']} robot and "
            f"{md['n_unknown_barcode_rows_in_window']} unknown-barcode rows "
            f"{'kept' if non_landmark == 'clutter' else 'dropped'}), true path {path_len:.1f} m"
            f"{_repairs_phrase(md['stamp_repairs'])}")


def _repairs_phrase(repairs: dict) -> str:
    """``"; repaired stamps: ..."`` for a summary line, or ``""`` when the files needed no repair."""
    from slamcli.datasets.mrclam import repair_summary

    text = repair_summary(repairs)
    return f"; {text}" if text else ""


@import_app.command("g2o")
def import_g2o_command(
    path: Annotated[
        Path,
        typer.Argument(
            help="Pose or landmark graph file: g2o (EDGE_SE2/EDGE_SE2_XY), TORO (EDGE2/LANDMARK2) or GTSAM "
            "text (ODOMETRY/LANDMARK/BR), e.g. dlr.g2o, or a dataset name (dlr, intel, manhattan, "
            "victoria-park-graph, ...; see `slamcli datasets list`)."
        ),
    ],
    dt: Annotated[float, typer.Option(help="Nominal sampling period, s (a graph has no time).")] = 1.0,
    forward: Annotated[
        choice("Forward", ("auto", "x", "y", "-x", "-y")),
        typer.Option(
            help="Forward axis of the file's body frame: auto (largest summed motion), x, y, -x or -y."
        ),
    ] = "auto",
    range_std: Annotated[
        float | None,
        typer.Option(help="σ_r to store, m (default: median of the propagated landmark covariances)."),
    ] = None,
    bearing_std: Annotated[
        float | None,
        typer.Option(help="σ_b to store, rad (default: median of the propagated landmark covariances)."),
    ] = None,
    max_poses: Annotated[
        int | None,
        typer.Option("--max-poses", help="Keep only the first N poses (ascending ids) and the edges among them."),
    ] = None,
    convention: Annotated[
        str,
        typer.Option(
            "--convention", click_type=click.Choice(["auto", "g2o", "toro", "gtsam", "isam"]),
            metavar="[auto|g2o|toro|gtsam|isam]",
            help="How edge numbers are read: auto (per tag: EDGE_SE2 g2o information, EDGE2 TORO information, "
            "ODOMETRY/LANDMARK covariance), g2o (information, g2o order), toro (information, TORO order), gtsam "
            "(covariance as GTSAM's load2D; LANDMARK as bearing-range), isam (square-root information; landmark "
            "ids in their own space)."),
    ] = "auto",
    quiet: _Quiet = False,
    out: _Out = None,
    force: _Force = False,
) -> None:
    """Import a pose graph or landmark graph losslessly: the odometry chain, loop closures as between-factors,
    landmark sightings as range-bearing rows with the file's landmark ids as reported ids, every edge's
    information matrix. No ground truth (solvers run; evaluate cannot)."""
    with handle_errors():
        if out is None:
            fail("-o/--out is required")
        from slamcli.datasets.g2o import import_graph
        from slamcli.datasets.registry import resolve_source
        from slamcli.io import write_dataset

        path = resolve_source(path, "g2o")  # (first: a registered name's file is the input)
        check_output(out, inputs=[path], kind="dataset", force=force)
        ds = import_graph(
            path, dt=dt, forward=str(forward), range_std=range_std, bearing_std=bearing_std, max_poses=max_poses,
            convention=convention,
        )
        write_dataset(out, ds)
        if quiet:
            return
        inp, md = ds.inputs, ds.metadata
        n = inp.noise
        stdout_console().print(
            f"{path.name}: {inp.n_poses} poses, {md['n_loop_closures']} loop closures, {md['n_landmarks']} "
            f"landmarks, {len(inp.observations)} observations, "
            f"forward axis {md['forward_axis']}; median σ odometry {[round(float(s), 5) for s in n.odometry_std]}, "
            f"range {n.range_std:.4g} m, bearing {n.bearing_std:.4g} rad; no ground truth → {out}"
            f"\n  {_convention_summary(md)}"
            + (f"\n  note: {md['import_note']}" if md.get("import_note") else ""),
            highlight=False,
            markup=False,
            soft_wrap=True,
        )


def _convention_summary(md: dict) -> str:
    """One line: the convention the graph was read with and what it made of each tag."""
    readings = "; ".join(f"{tag} {' / '.join(how)}" for tag, how in md["convention_readings"].items())
    merged = md.get("equiv_merged") or []
    return (f"convention {md['convention']}: {readings}; landmark ids: {md['landmark_id_space']}"
            + (f"; EQUIV merged {len(merged)} pose(s), dropping {md['equiv_dropped_edges']} edge(s) between merged "
               f"poses (a constant {md['equiv_dropped_cost']:.6g} of the cost)" if merged else ""))


_RangeStd = Annotated[float | None, typer.Option(help="σ_r to store, m (default: the importer's, see its docstring).")]
_BearingStd = Annotated[float | None, typer.Option(help="σ_b to store, rad (default: the importer's).")]
_VStd = Annotated[float | None, typer.Option(help="σ of the encoder speed, m/s (default: the importer's).")]
_SteerStd = Annotated[float | None, typer.Option(help="σ of the steering angle, rad (default: the importer's).")]


def _import_car_recording(out: Path | None, quiet: bool, load, summary, directory: Path, force: bool,
                          importer: str) -> None:
    """The shared body of the car-recording imports: ``directory`` (a folder or a registered name of
    ``importer``) resolved, ``load(folder)`` → Dataset, written atomically to ``out``, then ``summary(ds)``
    (one line) unless ``quiet``; every failure is one line (handle_errors)."""
    with handle_errors():
        if out is None:
            fail("-o/--out is required")
        from slamcli.datasets.registry import resolve_source
        from slamcli.io import write_dataset

        folder = resolve_source(directory, importer)
        check_output(out, inputs=[folder], kind="dataset", force=force)
        ds = load(folder)
        write_dataset(out, ds)
        if not quiet:
            stdout_console().print(f"{summary(ds)} → {out}", highlight=False, markup=False, soft_wrap=True)


@import_app.command("victoria-park")
def import_victoria_park_command(
    directory: Annotated[
        Path, typer.Argument(help="Victoria Park ASCII folder (inputs.dat, measurements.dat, gps.dat) or the "
                             "dataset name victoria-park.")
    ],
    start: Annotated[float, typer.Option(help="Window start, s after the first input row.")] = 0.0,
    duration: Annotated[float | None, typer.Option(help="Window length, s (default: to the end).")] = None,
    max_range: Annotated[float, typer.Option(help="Sensor max range to store, m.")] = float("inf"),
    range_std: _RangeStd = None,
    bearing_std: _BearingStd = None,
    v_std: _VStd = None,
    steer_std: _SteerStd = None,
    quiet: _Quiet = False,
    out: _Out = None,
    force: _Force = False,
) -> None:
    """Import Sydney Victoria Park: 40 Hz speed/steering as Ackermann controls, laser at (3.78, 0.50) m, tree
    detections without identities (trunk diameter kept per row), GPS as a position-only reference."""

    def load(folder):
        from slamcli.datasets.victoria_park import default_noise, import_victoria_park

        noise = default_noise(range_std=range_std, bearing_std=bearing_std, v_std=v_std, steer_std=steer_std)
        return import_victoria_park(folder, start=start, duration=duration, max_range=max_range, noise=noise)

    def summary(ds):
        inp, md = ds.inputs, ds.metadata
        return (f"Victoria Park: {inp.n_poses - 1} steps of {inp.dt:g} s, {md['n_scans']} scans, "
                f"{len(inp.observations)} tree detections (no ids), {md['n_gps_fixes']} GPS fixes "
                f"({md['gps_gaps_over_1s']} gaps > 1 s, longest {md['gps_longest_gap_s']:.1f} s)")

    _import_car_recording(out, quiet, load, summary, directory, force, "victoria-park")


@import_app.command("carpark")
def import_carpark_command(
    directory: Annotated[Path, typer.Argument(help="ACFR car-park folder (data_set.mat, beac_juan3.mat) or the dataset "
                                                    "name acfr-carpark.")],
    max_range: Annotated[float, typer.Option(help="Drop beacon returns beyond this range, m.")] = 81.0,
    range_std: _RangeStd = None,
    bearing_std: _BearingStd = None,
    v_std: _VStd = None,
    steer_std: _SteerStd = None,
    quiet: _Quiet = False,
    out: _Out = None,
    force: _Force = False,
) -> None:
    """Import the ACFR car park: Ackermann controls, beacons extracted from high-intensity laser returns (no
    ids), the 15 surveyed beacons as landmark truth and GPS as the path reference."""

    def load(folder):
        from slamcli.datasets.carpark import default_noise, import_carpark

        noise = default_noise(range_std=range_std, bearing_std=bearing_std, v_std=v_std, steer_std=steer_std)
        return import_carpark(folder, max_range=max_range, noise=noise)

    def summary(ds):
        inp, md = ds.inputs, ds.metadata
        return (f"ACFR car park: {inp.n_poses - 1} steps of {inp.dt:g} s, {md['n_scans']} scans, "
                f"{md['n_beacon_observations']} beacon observations (intensity >= "
                f"{md['beacon_intensity_threshold']}), {md['n_surveyed_beacons']} surveyed beacons, "
                f"{md['n_gps_fixes']} GPS fixes")

    _import_car_recording(out, quiet, load, summary, directory, force, "carpark")
