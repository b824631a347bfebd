"""Suite-wide pytest hooks and shared fixtures.

The hooks: what a test reports is sent between pytest-xdist's processes as UTF-8, and the
bad-input tests make file names that are not UTF-8 (legal on Linux, ``\\udcXX`` in Python strings); a report or
warning naming one would otherwise end the whole run with an internal error. Such bytes are shown escaped."""

from __future__ import annotations

import pytest


def _utf8(text: str) -> str:
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


@pytest.hookimpl(tryfirst=True)
def pytest_warning_recorded(warning_message, when, nodeid, location):
    text = str(warning_message.message)
    if _utf8(text) != text:
        category = type(warning_message.message)
        warning_message.message = category(_utf8(text)) if issubclass(category, Warning) else _utf8(text)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    report = (yield).get_result()
    if report.longrepr is not None and _utf8(str(report.longrepr)) != str(report.longrepr):
        report.longrepr = _utf8(str(report.longrepr))
    report.sections = [(title, _utf8(text)) for title, text in report.sections]


@pytest.fixture()
def shared_datasets(tmp_path, monkeypatch):
    """``lay_out({registry folder: tests/data excerpt})``: a shared datasets folder ``tmp_path/shared``
    (``$SLAMCLI_DATASETS``) holding copies of those excerpts under the registry's folder names, an empty data
    folder ``tmp_path/cache`` for the import cache, and no user registry; returns ``tmp_path``."""
    import shutil
    from pathlib import Path

    from slamcli.datasets import registry as reg

    def lay_out(folders: dict[str, str]):
        root = tmp_path / "shared"
        for folder, excerpt in folders.items():
            shutil.copytree(Path(__file__).parent / "data" / excerpt, root / folder)
        monkeypatch.setenv(reg.ENV_SHARED, str(root))
        monkeypatch.setenv(reg.ENV_DATA_DIR, str(tmp_path / "cache"))
        monkeypatch.delenv(reg.ENV_REGISTRY, raising=False)
        return tmp_path

    return lay_out
