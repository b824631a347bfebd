"""``slamcli datasets`` and dataset names in the importers (issue 24 item 2), on a local ``file://`` registry
(``$SLAMCLI_DATASET_REGISTRY``) built from the excerpts in tests/data — never the network.

References: sha256 values computed here with hashlib from the source files; imports by name compared with
imports of the same folder by path (``slamcli diff``, which skips the recorded source path).
"""

from __future__ import annotations

import hashlib
import shutil
import zipfile
from pathlib import Path

import h5py
import pytest
from conftest import DATA
from typer.testing import CliRunner

from slamcli.cli import app
from slamcli.datasets import registry as reg

VP = DATA / "victoria_park_excerpt"
runner = CliRunner()


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _file_entry(name, importer, marker, files, folder=None) -> str:
    rows = ", ".join(f'{{path = "{path}", url = "{src.as_uri()}"' + (f', sha256 = "{sha}"' if sha else "")
                     + (", unzip = true" if path.endswith(".zip") else "") + "}" for path, src, sha in files)
    return (f'[[dataset]]\nname = "{name}"\ntitle = "{name} (test)"\nimporter = "{importer}"\nmarker = "{marker}"\n'
            f'folder = "{folder or name}"\nfiles = [{rows}]\n')


@pytest.fixture()
def env(tmp_path, monkeypatch):
    """A data folder and a local registry: vp-test (sha256 known), vp-bad (wrong sha256), mr-test (a zip
    archive without sha256, like the MRCLAM downloads)."""
    zpath = tmp_path / "mirror" / "MRCLAM_Test.zip"
    zpath.parent.mkdir()
    with zipfile.ZipFile(zpath, "w") as z:
        for f in sorted((DATA / "mrclam_excerpt").glob("*.dat")):
            z.write(f, f"mrclam_excerpt/{f.name}")  # the folder name goes into @scenario
    vp_files = [(f"ascii/{n}", VP / n, _sha(VP / n)) for n in ("inputs.dat", "measurements.dat", "gps.dat")]
    text = (_file_entry("vp-test", "victoria-park", "ascii/inputs.dat", vp_files, folder="vp_folder")
            + _file_entry("vp-bad", "victoria-park", "ascii/inputs.dat", [("ascii/inputs.dat", VP / "inputs.dat", "0" * 64)])
            + _file_entry("mr-test", "mrclam", "Barcodes.dat", [("MRCLAM_Test.zip", zpath, None)]))
    (tmp_path / "registry.toml").write_text(text)
    monkeypatch.setenv(reg.ENV_REGISTRY, str(tmp_path / "registry.toml"))
    monkeypatch.setenv(reg.ENV_DATA_DIR, str(tmp_path / "data"))
    monkeypatch.delenv(reg.ENV_SHARED, raising=False)
    return tmp_path


def _run(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_builtin_registry_is_complete_and_honest_about_hashes():
    r = {e.name: e for e in reg.BUILTIN}
    names = {e.name for e in reg.BUILTIN}
    assert len(names) == len(reg.BUILTIN)  # unique
    assert {f"mrclam{n}" for n in range(1, 10)} | {"victoria-park", "acfr-carpark", "dlr", "intel", "mit", "csail",
                                                   "manhattan", "city10000", "kitti-00"} <= names
    for e in r.values():
        assert e.files and e.homepage.startswith("http") and e.citation and e.licence
        assert all(f.url.startswith(("https://", "http://")) for f in e.files)
        if not e.sha256_known:  # said so where a user reads it
            assert "sha256" in e.note and "unknown" in e.note
    assert not any(e.sha256_known for e in r.values() if e.importer == "mrclam")


def test_missing_dataset_is_one_line_naming_fetch(env):
    res = _run("datasets", "path", "vp-test")
    assert res.exit_code == 1 and res.stdout == ""
    assert res.stderr == ("error: dataset 'vp-test' is not on this machine: run `slamcli datasets fetch vp-test` "
                          "(or `slamcli datasets add vp-test DIR` for a copy you have)\n")
    res = _run("import", "victoria-park", "vp-test", "-o", env / "vp.h5")
    assert res.exit_code == 1 and "slamcli datasets fetch vp-test" in res.stderr and not (env / "vp.h5").exists()
    res = _run("import", "victoria-park", "no-such-name", "-o", env / "vp.h5")
    assert res.exit_code == 1 and "not a dataset name" in res.stderr


@pytest.mark.slow
def test_fetch_checks_sha256_and_import_by_name_equals_import_by_path(env):
    res = _run("datasets", "fetch", "vp-test", "-q")
    assert res.exit_code == 0, res.output
    folder = env / "data" / "vp-test" / "ascii"
    assert res.stdout.strip() == str(folder)
    for n in ("inputs.dat", "measurements.dat", "gps.dat"):
        assert _sha(folder / n) == _sha(VP / n)
    assert _run("datasets", "path", "vp-test").stdout.strip() == str(folder)
    assert "vp-test" in _run("datasets", "list").stdout.split("fetched")[0].splitlines()[-1]
    info = _run("datasets", "info", "vp-test").stdout
    assert f"file: ascii/gps.dat <- {(VP / 'gps.dat').as_uri()} (sha256 {_sha(VP / 'gps.dat')})" in info
    assert f"here: {folder} (fetched)" in info
    a = _run("import", "victoria-park", "vp-test", "--duration", "5", "-q", "-o", env / "a.h5")
    b = _run("import", "victoria-park", VP, "--duration", "5", "-q", "-o", env / "b.h5")
    assert a.exit_code == 0 and b.exit_code == 0, a.output + b.output
    assert _run("diff", env / "a.h5", env / "b.h5").exit_code == 0
    with h5py.File(env / "a.h5") as f:
        assert len(f["inputs/controls"]) == 200  # 5 s at 40 Hz: the import is not empty


def test_fetch_with_wrong_sha256_fails_in_one_line_and_leaves_nothing(env):
    res = _run("datasets", "fetch", "vp-bad")
    assert res.exit_code == 1
    err = [x for x in res.stderr.splitlines() if x.startswith("error:")]
    assert len(err) == 1 and "does not match the known hash" in err[0]
    assert not list((env / "data").rglob("inputs.dat"))


@pytest.mark.slow
def test_fetch_unzips_and_reports_the_unknown_sha256(env):
    res = _run("datasets", "fetch", "mr-test")
    assert res.exit_code == 0, res.output
    zsha = _sha(env / "mirror" / "MRCLAM_Test.zip")
    assert f"note: MRCLAM_Test.zip: sha256 unknown to the registry; downloaded file's is {zsha}" in res.stderr
    assert res.stdout.strip() == str(env / "data" / "mr-test" / "mrclam_excerpt")
    res = _run("import", "mrclam", "mr-test", "--robot", "1", "-q", "-o", env / "m.h5")
    assert res.exit_code == 0, res.output
    ref = _run("import", "mrclam", DATA / "mrclam_excerpt", "--robot", "1", "-q", "-o", env / "ref.h5")
    assert ref.exit_code == 0 and _run("diff", env / "m.h5", env / "ref.h5").exit_code == 0


@pytest.mark.slow
def test_add_registers_a_local_copy_and_checks_it(env):
    copy = env / "lab" / "vp_folder" / "ascii"
    copy.mkdir(parents=True)
    for n in ("inputs.dat", "measurements.dat", "gps.dat"):
        shutil.copyfile(VP / n, copy / n)
    res = _run("datasets", "add", "vp-test", copy.parent)
    assert res.exit_code == 0 and res.stdout.strip() == f"vp-test: added {copy}"
    assert _run("datasets", "path", "vp-test").stdout.strip() == str(copy)
    assert not (env / "data" / "vp-test").exists()  # nothing downloaded
    # the registration is one JSON file in the data folder, written atomically (no temporaries left)
    assert sorted(p.name for p in (env / "data").iterdir()) == ["registered.json"]
    # a folder without the marker, an unknown name, a modified file: refused in one line
    res = _run("datasets", "add", "vp-test", env / "lab")
    assert res.exit_code == 1 and "no ascii/inputs.dat in it" in res.stderr
    assert _run("datasets", "add", "nonesuch", copy).exit_code == 1
    with open(copy / "gps.dat", "a") as fh:
        fh.write("0 0 0\n")
    res = _run("datasets", "add", "vp-test", copy.parent)
    assert res.exit_code == 1 and "gps.dat: sha256 differs" in res.stderr
    # an added copy that disappeared is named, not silently replaced
    shutil.rmtree(copy)
    res = _run("datasets", "path", "vp-test")
    assert res.exit_code == 1 and "has no ascii/inputs.dat any more" in res.stderr


def test_slamcli_datasets_folder_is_used_and_a_typo_is_an_error(env, monkeypatch):
    shared = env / "shared"
    (shared / "vp_folder" / "ascii").mkdir(parents=True)
    shutil.copyfile(VP / "inputs.dat", shared / "vp_folder" / "ascii" / "inputs.dat")
    monkeypatch.setenv(reg.ENV_SHARED, str(shared))
    assert _run("datasets", "path", "vp-test").stdout.strip() == str(shared / "vp_folder" / "ascii")
    monkeypatch.setenv(reg.ENV_SHARED, str(env / "shraed"))
    res = _run("datasets", "path", "vp-test")
    assert res.exit_code == 1 and res.stderr.startswith(f"error: {reg.ENV_SHARED}=") and "no such folder" in res.stderr


def test_a_broken_registry_file_is_one_line(env, monkeypatch):
    (env / "bad.toml").write_text('[[dataset]]\nname = "x"\nimporter = "ply"\nmarker = "a"\n')
    monkeypatch.setenv(reg.ENV_REGISTRY, str(env / "bad.toml"))
    res = _run("datasets", "list")
    assert res.exit_code == 1 and "importer must be one of" in res.stderr and res.stderr.count("\n") == 1


@pytest.mark.parametrize("field, value", [("marker", "../../../../etc/passwd"), ("marker", "/etc/passwd"),
                                          ("marker", "a/../../b"), ("folder", ".."), ("folder", "../x"),
                                          ("folder", "a/b"), ("folder", "/etc"), ("name", "x\\n"),
                                          ("marker", "in\\u001b[31mputs.dat")])
@pytest.mark.slow
def test_registry_entries_that_would_leave_the_data_folder_are_refused(env, monkeypatch, field, value):
    """A registry entry's name, marker and folder are joined onto the data folder: each must stay inside it."""
    table = {"name": "evil", "importer": "victoria-park", "marker": "inputs.dat", "folder": "evil"}
    table[field] = value
    text = "[[dataset]]\n" + "".join(f'{k} = "{v}"\n' for k, v in table.items())
    (env / "evil.toml").write_text(text)
    monkeypatch.setenv(reg.ENV_REGISTRY, str(env / "evil.toml"))
    monkeypatch.setenv(reg.ENV_SHARED, "/")  # a marker "../../etc/passwd" would be found from here
    for args in (("datasets", "list"), ("datasets", "path", "evil"), ("import", "victoria-park", "evil", "-o",
                                                                       env / "o.h5")):
        res = _run(*args)
        assert res.exit_code == 1 and res.stderr.count("\n") == 1, (args, res.output)
        assert str(env / "evil.toml") in res.stderr and field in res.stderr
        assert "\x1b" not in res.stderr
    assert not (env / "o.h5").exists()


@pytest.mark.parametrize("which", ["registry", "registered"])
def test_deeply_nested_registry_files_are_one_line(env, monkeypatch, which):
    deep = "[" * 100_000 + "]" * 100_000
    if which == "registry":
        (env / "deep.toml").write_text(f"[[dataset]]\nname = \"x\"\nv = {deep}\n")
        monkeypatch.setenv(reg.ENV_REGISTRY, str(env / "deep.toml"))
        named = "deep.toml"
    else:
        (env / "data").mkdir()
        (env / "data" / "registered.json").write_text(deep)
        named = "registered.json"
    res = _run("datasets", "list")
    assert res.exit_code == 1 and res.stderr.count("\n") == 1 and named in res.stderr, res.output
    assert "nested too deeply" in res.stderr


def test_fetch_without_network_is_one_line_that_names_datasets_add(env, monkeypatch):
    """A download that cannot connect (here a closed port on 127.0.0.1: loopback only) says so in one line and
    names the command that registers a local copy, without the HTTP library's connection-pool text."""
    import socket

    with socket.socket() as s:  # a port nothing listens on once the socket is closed
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    text = _file_entry("off-test", "victoria-park", "ascii/inputs.dat", [])
    text = text.replace("files = []", f'files = [{{path = "ascii/inputs.dat", url = "http://127.0.0.1:{port}/i.dat"}}]')
    (env / "offline.toml").write_text(text)
    monkeypatch.setenv(reg.ENV_REGISTRY, str(env / "offline.toml"))
    res = _run("datasets", "fetch", "off-test", "-q")
    assert res.exit_code == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: off-test: "), res.stderr
    assert "cannot reach 127.0.0.1" in lines[0] and "slamcli datasets add off-test DIR" in lines[0]
    assert "Pool" not in lines[0] and "Max retries" not in lines[0] and "Errno" not in lines[0]


def test_datasets_list_has_a_header_over_its_columns(env):
    lines = _run("datasets", "list").stdout.splitlines()
    assert lines[0].split() == ["name", "importer", "here", "checksum", "title"]
    row = next(ln for ln in lines if ln.startswith("vp-test "))
    assert row.index("victoria-park") == lines[0].index("importer")  # the header stands over its column
