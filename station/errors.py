"""Errors that end a command with a known exit status and one clear line."""

from __future__ import annotations


class BadInput(Exception):
    """Bad configuration, CSV or arguments: exit 2. The message names the field or line."""


class RunFailed(Exception):
    """The run failed or was aborted (exit 1) with everything recorded so far kept."""
