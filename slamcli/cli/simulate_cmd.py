"""``slamcli simulate``: simulate a named scenario and write a dataset file."""

from __future__ import annotations

import contextlib
from pathlib import Path

import typer

from slamcli.cli.app import app, check_output, fail, handle_errors, progress_bar, stdout_console


@app.command("simulate")
def simulate_command(
    scenario: str = typer.Option(None, "--scenario", "-s", help="Scenario name (see --list)."),
    seed: int = typer.Option(0, "--seed", help="Root seed of the world/motion/odometry/sensor/clutter streams."),
    set_: list[str] = typer.Option(
        None, "--set", help="Override key=value with dotted keys, e.g. sensor.max_range=10 (repeatable)."
    ),
    list_: bool = typer.Option(False, "--list", help="List the scenarios and exit."),
    keys: bool = typer.Option(False, "--keys", help="List the override keys of --scenario with their values."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar and no summary."),
    out: Path = typer.Option(None, "-o", "--out", help="Dataset file to write (HDF5, written atomically)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing -o that is not a slamcli dataset file."),
) -> None:
    """Simulate --scenario with --seed and write the dataset (inputs + ground truth) to -o."""
    with handle_errors():
        if list_:
            from slamcli.sim import list_scenarios

            console = stdout_console()
            import textwrap

            for name, desc in list_scenarios():  # hanging indent, 80 columns
                text = textwrap.fill(f"{name:<12} {desc}", 80, subsequent_indent=" " * 13)
                console.print(f"[bold]{name}[/bold]{text[len(name):]}", highlight=False, soft_wrap=True)
            return
        if scenario is None:
            fail("--scenario is required (see `slamcli simulate --list`)")
        from slamcli.api.simulate import parse_overrides, simulate_to_file
        from slamcli.sim import config_to_dict, resolve_scenario

        if not 0 <= seed < 2**63:
            fail(f"--seed: must be in [0, 2^63), got {seed}")
        overrides = parse_overrides(list(set_ or []))
        cfg = resolve_scenario(scenario, overrides)  # validate before anything runs
        if keys:
            flat = config_to_dict(cfg)
            console = stdout_console()
            for k, v in flat.items():
                if isinstance(v, dict):
                    for kk, vv in v.items():
                        console.print(f"{k}.{kk} = {vv}", highlight=False, markup=False)
                elif k != "name":
                    console.print(f"{k} = {v}", highlight=False, markup=False)
            return
        if out is None:
            fail("-o/--out is required")
        check_output(out, kind="dataset", force=force)
        # The bar opens on the first progress report (after the world is built), so errors print one line.
        with contextlib.ExitStack() as stack:
            bar: list = []

            def progress(done: int, total: int) -> None:
                if not bar:
                    bar.append(stack.enter_context(progress_bar(f"simulate {scenario}", quiet=quiet)))
                bar[0](done, total)

            ds = simulate_to_file(scenario, seed, overrides, out, progress=progress)
        if quiet:
            return
        import numpy as np

        inp, tr = ds.inputs, ds.truth
        n_obs = len(inp.observations)
        n_clutter = int(np.sum(tr.obs_landmark < 0)) if tr is not None else 0
        path_len = float(np.sum(np.hypot(*np.diff(tr.poses_xyt[:, :2], axis=0).T))) if tr is not None else 0.0
        stdout_console().print(
            f"{scenario} seed {seed}: {inp.controls.shape[0]} steps ({inp.controls.shape[0] * inp.dt:.1f} s), "
            f"path {path_len:.1f} m\n  {len(tr.landmarks_xy)} landmarks, {n_obs} observations ({n_clutter} not "
            f"from a landmark)\n  wrote {out}",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
