"""Registry of the public recordings slamcli imports: where each one comes from, its licence and citation, and
where it is on this machine (``slamcli datasets list | fetch NAME | path NAME | add NAME DIR | info NAME``).

Where a recording is looked for, in this order (:func:`locate`):

1. a local copy registered with ``slamcli datasets add NAME DIR`` (offline machines, a lab's shared folder,
   CI): recorded in ``registered.json`` of the data folder;
2. ``$SLAMCLI_DATASETS/<folder>`` when that variable is set: a folder laid out like the project's shared
   datasets folder (one subfolder per recording, :attr:`DatasetEntry.folder`). A value that is not a folder is
   an error (one line), never a silent fall-back;
3. the copy ``slamcli datasets fetch NAME`` downloaded into the data folder: ``$SLAMCLI_DATA_DIR``, else the
   per-user cache folder of ``platformdirs`` (``user_cache_dir("slamcli")/datasets``).

None found: :class:`DatasetMissingError`, one line naming the fetch command. Downloads go through ``pooch``
(into a temporary name, then renamed; the sha256 is checked where the registry knows it — where it does not,
the entry says so and ``fetch`` prints the downloaded file's sha256). ``$SLAMCLI_DATASET_REGISTRY`` names a
TOML file whose ``[[dataset]]`` tables replace or add entries (a mirror, or the tests' local ``file://``
registry; ``file://`` URLs are copied, never fetched over the network).

The sha256 values below were computed from the copies in the project's shared datasets folder, whose
PROVENANCE.txt records each as an unmodified copy of the pinned URL; the MRCLAM archives' sha256 is unknown.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import urllib.parse
from dataclasses import dataclass
from pathlib import Path

from slamcli.datasets import DatasetImportError

ENV_DATA_DIR = "SLAMCLI_DATA_DIR"
ENV_SHARED = "SLAMCLI_DATASETS"
ENV_REGISTRY = "SLAMCLI_DATASET_REGISTRY"
#: the importers a recording can be read with (``slamcli import <importer>``)
IMPORTERS = ("mrclam", "victoria-park", "carpark", "g2o")
_NAME = re.compile(r"[a-z][a-z0-9-]*")  # (fullmatch: ``$`` would accept a final newline)
_SHA256 = re.compile(r"[0-9a-f]{64}")
#: one file or folder name: no separator, not ``.``/``..``, no control character
_COMPONENT = re.compile(r"(?!\.{1,2}\Z)[^/\\\x00-\x1f\x7f]+")


def _check_relative(value: object, what: str, *, single: bool = False) -> None:
    """Raise ValueError unless ``value`` is a relative path of plain names (``single``: exactly one name), so
    that joining it onto a folder cannot leave that folder (no ``..``, no absolute path)."""
    parts = value.split("/") if isinstance(value, str) else []
    if not parts or (single and len(parts) > 1) or not all(_COMPONENT.fullmatch(c) for c in parts):
        how = "one file or folder name" if single else "a relative path of plain names"
        raise ValueError(f"{what} must be {how} (no '..', '/' at the start or control characters), got {value!r}"[:200])


class DatasetMissingError(DatasetImportError):
    """A registered recording that is not on this machine (the message names the fetch command)."""


class DatasetFetchError(DatasetImportError):
    """A download that failed or whose sha256 differs from the registry's."""


@dataclass(frozen=True)
class RemoteFile:
    """One file of a recording: ``path`` inside the recording's folder, where to download it, its sha256
    (``None`` = not known) and whether it is a zip archive to unpack there."""

    path: str
    url: str
    sha256: str | None = None
    unzip: bool = False

    def __post_init__(self) -> None:
        _check_relative(self.path, "file path")
        if urllib.parse.urlparse(self.url).scheme not in ("https", "http", "ftp", "file"):
            raise ValueError(f"{self.path}: url must be https/http/ftp/file, got {self.url!r}")
        if self.sha256 is not None and not (isinstance(self.sha256, str) and _SHA256.fullmatch(self.sha256)):
            raise ValueError(f"{self.path}: sha256 must be 64 lowercase hex digits or absent")


@dataclass(frozen=True)
class DatasetEntry:
    """A public recording.

    ``marker`` is a file that identifies the recording (relative to its folder); the importer reads the folder
    that holds it (``g2o``: the marker file itself). ``folder`` is the recording's subfolder in a shared
    datasets folder (``$SLAMCLI_DATASETS``).
    """

    name: str
    title: str
    importer: str
    marker: str
    folder: str
    homepage: str
    licence: str
    citation: str
    files: tuple[RemoteFile, ...] = ()
    note: str = ""

    def __post_init__(self) -> None:
        if not (isinstance(self.name, str) and _NAME.fullmatch(self.name)):
            raise ValueError(f"dataset name must be lowercase letters, digits and '-', got {self.name!r}")
        if self.importer not in IMPORTERS:
            raise ValueError(f"{self.name}: importer must be one of {', '.join(IMPORTERS)}, got {self.importer!r}")
        _check_relative(self.marker, f"{self.name}: marker")
        _check_relative(self.folder, f"{self.name}: folder", single=True)

    @property
    def sha256_known(self) -> bool:
        return bool(self.files) and all(f.sha256 for f in self.files)


_GH = "https://raw.githubusercontent.com"
_SESYNC = f"{_GH}/david-m-rosen/SE-Sync/9b631b6b82d8aa7d32ab846412ae1c070412b7b6/data"
_RFS = f"{_GH}/kykleung/RFS-SLAM/aa5170be675391642c7ecfe6c7a3d39d218e674d/data/VictoriaPark"
_MRCLAM_CITE = ("K. Y. K. Leung, Y. Halpern, T. D. Barfoot, H. H. T. Liu, \"The UTIAS multi-robot cooperative "
                "localization and mapping dataset\", International Journal of Robotics Research 30(8):969-974, 2011")
_SESYNC_CITE = ("D. M. Rosen, L. Carlone, A. S. Bandeira, J. J. Leonard, \"SE-Sync: a certifiably correct algorithm "
                "for synchronization over the special Euclidean group\", International Journal of Robotics Research "
                "38(2-3):95-125, 2019")
_NOT_STATED = "not stated by the source (cite the publication; ask the authors before redistributing)"


def _mrclam(n: int) -> DatasetEntry:
    return DatasetEntry(
        name=f"mrclam{n}", title=f"UTIAS MRCLAM Dataset {n} (5 robots, 15 landmarks, motion-capture truth)",
        importer="mrclam", marker="Barcodes.dat", folder=f"mrclam_dataset{n}",
        homepage="http://asrl.utias.utoronto.ca/datasets/mrclam/", licence=_NOT_STATED, citation=_MRCLAM_CITE,
        files=(RemoteFile(f"MRCLAM_Dataset{n}.zip",
                          f"http://asrl.utias.utoronto.ca/datasets/mrclam/MRCLAM_Dataset{n}.zip", None, unzip=True),),
        note="sha256 of the official archive unknown: fetch prints the downloaded one",
    )


def _pose_graph(name: str, file: str, title: str, original: str) -> DatasetEntry:
    return DatasetEntry(
        name=name, title=f"{title} pose graph (g2o, SE-Sync benchmark set; no ground truth)", importer="g2o",
        marker=file, folder="pose_graphs", homepage="https://github.com/david-m-rosen/SE-Sync",
        licence=_NOT_STATED, citation=f"{_SESYNC_CITE}; original data: {original}",
        files=(RemoteFile(file, f"{_SESYNC}/{file}", _POSE_GRAPH_SHA[file]),),
    )


_POSE_GRAPH_SHA = {
    "intel.g2o": "3e0724c048e0ba524be9dd268a8b78e19a2497043143584cbb61310638b15c4b",
    "MIT.g2o": "e5922be0d0689c7a5bc04c58adf3a8e697e240bdd7691cc4218470eaf92956eb",
    "CSAIL.g2o": "66d99ac857a9849d814d214a9ebd0d4876d5d40f0a37be9330c1ff6e6e9daaa6",
    "manhattan.g2o": "6ae8d30971720c1af24a00c4b2dd5c5ddafbbbe488bfc771145c47decbffb248",
    "city10000.g2o": "df5988994339e990be198a36e7f640e31a5a1b26df3ed400363fafc49d5ca630",
    "kitti_00.g2o": "8a9807f604852a44254910100917918def94d7357748c633e1fd7ce73dd17468",
}

BUILTIN: tuple[DatasetEntry, ...] = (
    *(_mrclam(n) for n in range(1, 10)),
    DatasetEntry(
        name="victoria-park", title="Sydney Victoria Park (ACFR utility car, laser tree detections, GPS)",
        importer="victoria-park", marker="rfs_slam_ascii/inputs.dat", folder="victoria_park",
        homepage="http://www-personal.acfr.usyd.edu.au/nebot/victoria_park.htm", licence=_NOT_STATED,
        citation=("J. Guivant, E. Nebot, \"Optimization of the simultaneous localization and map-building algorithm "
                  "for real-time implementation\", IEEE Transactions on Robotics and Automation 17(3):242-257, 2001"),
        files=(
            RemoteFile("rfs_slam_ascii/inputs.dat", f"{_RFS}/inputs.dat",
                       "94353fa7a529f8a9e9770e69363d27472fe414f3637a107dce54a7f8db96e7d8"),
            RemoteFile("rfs_slam_ascii/measurements.dat", f"{_RFS}/measurements.dat",
                       "b0737e2d312cbb80d466a8f1d6048e11dd06939a5ffb63becc8b954cde149746"),
            RemoteFile("rfs_slam_ascii/gps.dat", f"{_RFS}/gps.dat",
                       "944657cdaacdb9c421bf3a7ec1af95f05a8b9fefb513374f1f617bacc5426c07"),
        ),
        note="the ASCII conversion of the original .mat logs distributed with K. Leung's RFS-SLAM",
    ),
    DatasetEntry(
        name="victoria-park-graph", title="Victoria Park landmark graph (GTSAM example file; no ground truth)",
        importer="g2o", marker="gtsam/victoria_park.txt", folder="victoria_park",
        homepage="https://github.com/borglab/gtsam", licence="BSD (GTSAM repository)",
        citation="GTSAM, examples/Data/victoria_park.txt; recording: Guivant & Nebot 2001 (see victoria-park)",
        files=(RemoteFile("gtsam/victoria_park.txt",
                          f"{_GH}/borglab/gtsam/0ffe6c930302ebd297484e65e6e8d467c91d26b0/examples/Data/victoria_park.txt",
                          "10596bac625acfe009080748b0ec9993fc9925a93370878c20288a22eeee5253"),),
    ),
    DatasetEntry(
        name="acfr-carpark", title="ACFR car park (Victoria Park car, 15 surveyed laser beacons, GPS)",
        importer="carpark", marker="data_set.mat", folder="acfr_carpark",
        homepage="http://www-personal.acfr.usyd.edu.au/nebot/experimental_data/", licence=_NOT_STATED,
        citation="ACFR, University of Sydney (E. Nebot's experimental data); same vehicle as Guivant & Nebot 2001",
        files=(
            RemoteFile("data_set.mat", f"{_GH}/yuzehai1995/hwork_SLAM/b4715234d795a5dd8155371e99b71f99803eb551/"
                       "hw4_slam/data_set.mat", "f44c8adfa7e8e38ea6c40da3cd5d52bd8e029fc2d5ea27a9d7df24ad4ec98be7"),
            RemoteFile("beac_juan3.mat", f"{_GH}/yuzehai1995/hwork_SLAM/b4715234d795a5dd8155371e99b71f99803eb551/"
                       "hw4_slam/beac_juan3.mat", "a6def97aef0e0f0d7a0a00f7014cdd1390fd8779ec7f17613c32b2e44aae1f36"),
        ),
        note="copy from a public course repository (no original ACFR download URL found); pinned commit and sha256",
    ),
    DatasetEntry(
        name="dlr", title="DLR Spatial Cognition landmark graph (g2o; no ground truth)", importer="g2o",
        marker="dlr.g2o", folder="dlr_g2o",
        homepage="https://www.informatik.uni-bremen.de/agebv/en/DlrSpatialCognitionDataSet", licence=_NOT_STATED,
        citation=("U. Frese, \"Treemap: an O(log n) algorithm for indoor simultaneous localization and mapping\", "
                  "Autonomous Robots 21(2):103-122, 2006"),
        files=(RemoteFile("dlr.g2o", f"{_GH}/jgsimard/RustRobotics/965cb64ba049580817bcaebc914b0163373e4e8c/"
                          "dataset/g2o/dlr.g2o", "76a2e0f0f7f32a1a41f023bff1da02745029f4ef65867a7958c8283540a2a02e"),),
        note="g2o conversion distributed with RustRobotics (the Bremen page ships the original text format)",
    ),
    _pose_graph("intel", "intel.g2o", "Intel Research Lab", "A. Howard, N. Roy, the Robotics Data Set Repository (Radish), 2003"),
    _pose_graph("mit", "MIT.g2o", "MIT Killian Court", "the Robotics Data Set Repository (Radish)"),
    _pose_graph("csail", "CSAIL.g2o", "MIT CSAIL", "the Robotics Data Set Repository (Radish)"),
    _pose_graph("manhattan", "manhattan.g2o", "Manhattan M3500",
                "E. Olson, J. Leonard, S. Teller, \"Fast iterative alignment of pose graphs with poor initial estimates\", ICRA 2006"),
    _pose_graph("city10000", "city10000.g2o", "City10000",
                "M. Kaess, A. Ranganathan, F. Dellaert, \"iSAM: incremental smoothing and mapping\", IEEE T-RO 24(6), 2008"),
    _pose_graph("kitti-00", "kitti_00.g2o", "KITTI odometry sequence 00 (planar)",
                "A. Geiger, P. Lenz, R. Urtasun, \"Are we ready for autonomous driving? The KITTI vision benchmark suite\", CVPR 2012"),
)


# -- the registry and the data folder ----------------------------------------------------------------------


def _entry_from_table(t: dict, src: str) -> DatasetEntry:
    try:
        files = tuple(RemoteFile(**f) for f in t.get("files", ()))
        rest = {k: v for k, v in t.items() if k != "files"}
        rest.setdefault("folder", rest.get("name", ""))
        for key in ("homepage", "licence", "citation", "title"):
            rest.setdefault(key, "")
        return DatasetEntry(files=files, **rest)
    except (TypeError, ValueError) as exc:
        raise DatasetImportError(f"{src}: dataset {t.get('name', '?')!r}: {exc}") from None


def _why(exc: BaseException) -> str:
    return "nested too deeply" if isinstance(exc, RecursionError) else str(exc).splitlines()[0][:160]


def registry() -> dict[str, DatasetEntry]:
    """Name → entry: the built-in entries, replaced or extended by ``$SLAMCLI_DATASET_REGISTRY`` (TOML)."""
    import tomllib

    out = {e.name: e for e in BUILTIN}
    extra = os.environ.get(ENV_REGISTRY)
    if extra:
        p = Path(extra)
        try:
            tables = tomllib.loads(p.read_text(encoding="utf-8")).get("dataset", [])
        except OSError as exc:
            raise DatasetImportError(f"{ENV_REGISTRY}={extra}: cannot read ({exc.strerror})") from None
        except tomllib.TOMLDecodeError as exc:
            raise DatasetImportError(f"{ENV_REGISTRY}={extra}: not valid TOML ({exc})") from None
        except (RecursionError, UnicodeDecodeError) as exc:
            raise DatasetImportError(f"{ENV_REGISTRY}={extra}: not valid TOML ({_why(exc)})") from None
        if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
            raise DatasetImportError(f"{ENV_REGISTRY}={extra}: [[dataset]] must be an array of tables")
        for t in tables:
            e = _entry_from_table(t, extra)
            out[e.name] = e
    return out


def entry(name: str) -> DatasetEntry:
    """The registry entry ``name``; unknown names are one line listing the known ones."""
    reg = registry()
    if name not in reg:
        raise DatasetImportError(f"{name!r} is not a registered dataset; known: {', '.join(sorted(reg))}")
    return reg[name]


def data_dir() -> Path:
    """``$SLAMCLI_DATA_DIR``, else ``platformdirs.user_cache_dir("slamcli")/datasets``."""
    env = os.environ.get(ENV_DATA_DIR)
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("slamcli")) / "datasets"


def _registered_file() -> Path:
    return data_dir() / "registered.json"


def registered() -> dict[str, str]:
    """Name → folder of the local copies registered with :func:`add`."""
    p = _registered_file()
    if not p.is_file():
        return {}
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:  # (JSONDecodeError and UnicodeDecodeError are ValueErrors)
        raise DatasetImportError(f"{p}: unreadable list of registered datasets ({_why(exc)}); delete it and "
                                 "re-add") from None
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise DatasetImportError(f"{p}: not a JSON object of dataset name -> folder; delete it and re-add")
    return data


def _find_marker(root: Path, marker: str) -> Path | None:
    """``root/marker``, else the marker's file name in ``root`` or in one of its immediate subfolders
    (an unpacked archive's top folder, or a DIR that already is the importer's folder)."""
    m = Path(marker)
    for cand in (root / m, root / m.name):
        if cand.is_file():
            return cand
    if root.is_dir():
        for sub in sorted(p for p in root.iterdir() if p.is_dir()):
            if (sub / m.name).is_file():
                return sub / m.name
    return None


def _import_path(e: DatasetEntry, marker_file: Path) -> Path:
    return marker_file if e.importer == "g2o" else marker_file.parent


def _shared_root() -> Path | None:
    env = os.environ.get(ENV_SHARED)
    if not env:
        return None
    p = Path(env).expanduser()
    if not p.is_dir():
        raise DatasetMissingError(f"{ENV_SHARED}={env}: no such folder (unset it, or use `slamcli datasets add`)")
    return p


def where(name: str) -> tuple[str, Path] | None:
    """``(how, import path)`` of recording ``name`` on this machine — how is ``added``, ``$SLAMCLI_DATASETS``
    or ``fetched`` — or None when it is not here (see the module docstring for the order)."""
    e = entry(name)
    reg = registered()
    if name in reg:
        f = _find_marker(Path(reg[name]), e.marker)
        if f is None:
            raise DatasetMissingError(f"{name}: the copy added at {reg[name]} has no {e.marker} any more; run "
                                      f"`slamcli datasets add {name} DIR` again or `slamcli datasets fetch {name}`")
        return "added", _import_path(e, f)
    shared = _shared_root()
    if shared is not None and (f := _find_marker(shared / e.folder, e.marker)) is not None:
        return f"${ENV_SHARED}", _import_path(e, f)
    if (f := _find_marker(data_dir() / name, e.marker)) is not None:
        return "fetched", _import_path(e, f)
    return None


def recording_folders() -> list[Path]:
    """Every folder on this machine that holds a registry recording (added, under ``$SLAMCLI_DATASETS`` or
    fetched), whether or not it is read now: the output guard treats them all as inputs. An unreadable
    registry or list of added copies contributes nothing here (the command that reads them reports it)."""
    found: list[Path] = []
    with contextlib.suppress(DatasetImportError):
        found += [Path(folder) for folder in registered().values()]
    with contextlib.suppress(DatasetImportError):
        entries = registry().values()
        shared = _shared_root()
        found += [shared / e.folder for e in entries if shared is not None] + [data_dir() / e.name for e in entries]
    return [p for p in found if p.is_dir()]


def locate(name: str) -> Path:
    """The path the importer of ``name`` reads; :class:`DatasetMissingError` (one line) when it is not here."""
    found = where(name)
    if found is None:
        raise DatasetMissingError(f"dataset {name!r} is not on this machine: run `slamcli datasets fetch {name}` "
                                  f"(or `slamcli datasets add {name} DIR` for a copy you have)")
    return found[1]


def resolve_source(arg: str | os.PathLike, importer: str) -> Path:
    """An importer's input given as a path or a dataset name: an existing path, or anything that looks like a
    path (a folder separator or a file suffix), is used as it is (the importer names a missing file); otherwise
    a registered name of this importer is located (:func:`locate`)."""
    p = Path(arg)
    name = str(arg)
    if p.exists() or os.sep in name or "/" in name or p.suffix:
        return p
    reg = registry()
    if name not in reg:
        raise DatasetImportError(f"{arg}: no such file or folder, and not a dataset name "
                                 f"(`slamcli datasets list` shows them)")
    if reg[name].importer != importer:
        raise DatasetImportError(f"{name} is read with `slamcli import {reg[name].importer}`, not {importer}")
    return locate(name)


# -- add / fetch ----------------------------------------------------------------------------------------


def sha256_of(path: str | os.PathLike) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def add(name: str, directory: str | os.PathLike) -> Path:
    """Register the local copy ``directory`` of recording ``name`` (checked: its marker file is there, and every
    file whose sha256 the registry knows matches it). Returns the path the importer will read."""
    from slamcli.io.atomic import atomic_path

    e = entry(name)
    root = Path(directory).expanduser().resolve()
    if not root.is_dir():
        raise DatasetImportError(f"{directory}: no such folder")
    marker = _find_marker(root, e.marker)
    if marker is None:
        raise DatasetImportError(f"{directory}: no {e.marker} in it — is it the {name} recording?")
    for f in e.files:
        local = root / f.path if (root / f.path).is_file() else marker.parent / Path(f.path).name
        if f.sha256 and not f.unzip and local.is_file() and sha256_of(local) != f.sha256:
            raise DatasetImportError(f"{local}: sha256 differs from the registry's ({f.sha256[:12]}…): "
                                     f"not the published file")
    reg = registered()
    reg[name] = str(root)
    target = _registered_file()
    target.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(target) as tmp:
        tmp.write_text(json.dumps(reg, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    return _import_path(e, marker)


def _copy_file_url(url: str, output_file, pooch_obj=None, check_only: bool = False):
    """pooch downloader for ``file://`` URLs (local mirrors, the tests' registry): a plain copy."""
    import urllib.request

    src = Path(urllib.request.url2pathname(urllib.parse.urlparse(url).path))
    if check_only:
        return src.is_file()
    if not src.is_file():
        raise DatasetFetchError(f"{url}: no such file")
    if hasattr(output_file, "write"):
        with open(src, "rb") as fh:
            shutil.copyfileobj(fh, output_file)
    else:
        shutil.copyfile(src, output_file)
    return None


def _download_failure(exc: BaseException, url: str) -> str:
    """Why a download failed, in a few words: the kind of network failure and the host, not the HTTP
    library's retry and connection-pool text."""
    from urllib.parse import urlsplit

    kinds = {c.__name__ for c in type(exc).__mro__}
    host = urlsplit(url).hostname or url
    if "HTTPError" in kinds:
        status = getattr(getattr(exc, "response", None), "status_code", None)
        return f"{host} answered HTTP {status}" if status else f"{host} refused the request"
    if kinds & {"ConnectionError", "Timeout", "TimeoutError", "gaierror"}:
        return f"cannot reach {host}: offline, or the network blocks it"
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0][:120]}" if text else type(exc).__name__


def fetch(name: str, progress=None) -> tuple[Path, list[str]]:
    """Download recording ``name`` into ``data_dir()/name`` (files already there with the right sha256 are kept).

    Returns the import path and one note per file whose sha256 the registry does not know (its sha256 as
    downloaded). Failures are one line (:class:`DatasetFetchError`).
    """
    import pooch

    pooch.get_logger().setLevel("WARNING")  # its "Downloading ..." lines: the CLI prints its own progress
    e = entry(name)
    if not e.files:
        raise DatasetFetchError(f"{name}: the registry has no download URL for it; use `slamcli datasets add {name} DIR`")
    dest = data_dir() / name
    notes = []
    for f in e.files:
        target = dest / f.path
        if progress is not None:
            progress(f"{name}: {f.url}")
        downloader = _copy_file_url if f.url.startswith("file:") else None
        processor = pooch.Unzip(extract_dir=".") if f.unzip else None
        try:
            pooch.retrieve(f.url, known_hash=f"sha256:{f.sha256}" if f.sha256 else None, fname=target.name,
                           path=target.parent, downloader=downloader, processor=processor)
        except ValueError as exc:  # pooch: hash mismatch
            raise DatasetFetchError(f"{name}: {f.path}: {str(exc).splitlines()[0]}") from None
        except DatasetFetchError:
            raise
        except Exception as exc:  # noqa: BLE001 — requests/ftplib/OSError: one line, not a traceback
            raise DatasetFetchError(f"{name}: {f.path}: download failed ({_download_failure(exc, f.url)}); "
                                    f"with a copy of the files, register it: slamcli datasets add {name} DIR") from None
        if not f.sha256:
            notes.append(f"{f.path}: sha256 unknown to the registry; downloaded file's is {sha256_of(target)}")
    marker = _find_marker(dest, e.marker)
    if marker is None:
        raise DatasetFetchError(f"{name}: downloaded, but no {e.marker} in {dest}")
    return _import_path(e, marker), notes
