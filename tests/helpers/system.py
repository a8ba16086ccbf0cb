"""What a test needs from the machine it runs on (a C compiler, LinuxCNC, root to
install a component), and the one rule for when it is missing: under CI (the
environment variable ``CI`` set, as every CI service sets it) the test fails, since
the CI image is meant to hold everything and a test skipped there proves nothing;
on a developer's machine it skips, saying what is missing."""

from __future__ import annotations

import os

import pytest


def in_ci() -> bool:
    return bool(os.environ.get("CI"))


def require(condition: bool, what: str) -> None:
    """Go on when ``condition`` holds; else fail under CI and skip elsewhere, with
    ``what`` (what the test needs, in a few words) as the reason."""
    if condition:
        return
    if in_ci():
        pytest.fail(f"CI must provide {what}", pytrace=False)
    pytest.skip(f"this machine lacks {what}")
