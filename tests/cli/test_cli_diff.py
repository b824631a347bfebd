"""``slamcli diff`` skips recorded file paths (issue 24 item 8) unless ``--paths``: two results of byte-identical
datasets kept in different folders are "same"; content changes are still found with the paths skipped."""

from __future__ import annotations

import json
import shutil

import h5py
import pytest
from typer.testing import CliRunner

from slamcli.api.simulate import simulate_to_file
from slamcli.api.solve import solve_file
from slamcli.cli import app
from slamcli.io.diff import diff_files, is_path_key

runner = CliRunner()


@pytest.fixture(scope="module")
def twins(tmp_path_factory):
    """One dataset copied into two folders, each solved there: the results differ only in recorded paths."""
    root = tmp_path_factory.mktemp("twins")
    (root / "a").mkdir()
    (root / "b" / "deeper").mkdir(parents=True)
    simulate_to_file("loop", 2, {"n_steps": 60}, root / "a" / "d.h5")
    shutil.copyfile(root / "a" / "d.h5", root / "b" / "deeper" / "d.h5")
    ra, rb = root / "a" / "r.h5", root / "b" / "r.h5"
    solve_file(root / "a" / "d.h5", "odometry", {}, ra)
    solve_file(root / "b" / "deeper" / "d.h5", "odometry", {}, rb)
    return root, ra, rb


def test_path_keys():
    assert all(is_path_key(k) for k in ("dataset_path", "dataset_relpath", "init_path", "source_dir", "source_file"))
    assert not any(is_path_key(k) for k in ("dataset_hash", "source", "pathology", "seed"))


def test_results_of_identical_datasets_in_other_folders_are_same(twins):
    _, ra, rb = twins
    with h5py.File(ra, "r") as fa, h5py.File(rb, "r") as fb:  # the files really record different paths
        assert fa.attrs["dataset_path"] != fb.attrs["dataset_path"]
        ea, eb = json.loads(fa.attrs["extra_json"]), json.loads(fb.attrs["extra_json"])
        assert ea["dataset_relpath"] == "d.h5" and eb["dataset_relpath"] == "deeper/d.h5"
    res = runner.invoke(app, ["diff", str(ra), str(rb)])
    assert res.exit_code == 0, res.output
    # @dataset_path, and extra_json's dataset_path + dataset_relpath
    assert res.stdout.startswith("same:") and "3 recorded paths; --paths compares them" in res.stdout
    res = runner.invoke(app, ["diff", "--paths", str(ra), str(rb)])
    assert res.exit_code == 1, res.output
    assert res.stdout.startswith("different: 2 of") and "@dataset_path" in res.stdout and "@extra_json" in res.stdout


def test_content_changes_are_still_found_without_paths(twins):
    root, ra, _ = twins
    c = root / "c.h5"
    shutil.copyfile(ra, c)
    with h5py.File(c, "r+") as f:
        extra = json.loads(f.attrs["extra_json"])
        extra["source_dir"] = "/elsewhere"  # a path key added: skipped
        extra["seed"] = extra["seed"] + 1  # content: found
        f.attrs["extra_json"] = json.dumps(extra)
    d = diff_files(ra, c)
    assert [k for k, _ in d.differences] == ["@extra_json"] and "seed" in d.differences[0][1]
    assert "source_dir" not in d.differences[0][1]
    with h5py.File(c, "r+") as f:
        f["poses_xyt"][2, 1] += 1e-9
    assert [k for k, _ in diff_files(ra, c).differences] == ["@extra_json", "poses_xyt"]
