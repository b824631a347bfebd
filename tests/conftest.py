"""Suite-wide pytest hooks."""

from __future__ import annotations

import pytest


@pytest.hookimpl(tryfirst=True)
def pytest_warning_recorded(warning_message, when, nodeid, location):
    """A warning whose text names a file that is not UTF-8 (legal on Linux; the bad-input tests make such
    names) is shown with the bytes escaped: pytest-xdist sends warnings between processes as UTF-8, and a
    lone surrogate there ends the whole run with an internal error."""
    text = str(warning_message.message)
    safe = text.encode("utf-8", "backslashreplace").decode("utf-8")
    if safe != text:
        warning_message.message = type(warning_message.message)(safe) if isinstance(
            warning_message.message, Warning) else safe
