"""One line for a config's validation error, naming the field path (pydantic's
errors in the words of the file: "machine.leg_length: must be > 0")."""

from __future__ import annotations

import re
from typing import Any

from pydantic import ValidationError
from pydantic_core import ErrorDetails


def _loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


def _message(err: ErrorDetails) -> str:
    kind, ctx = err["type"], err.get("ctx") or {}
    if kind == "extra_forbidden":
        return "unknown key"
    if kind == "missing":
        return "missing (required)"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        op = {"greater_than": ">", "greater_than_equal": ">=",
              "less_than": "<", "less_than_equal": "<="}[kind]
        bound = next(iter(ctx.values()))
        if isinstance(bound, float) and bound.is_integer():
            bound = int(bound)
        return f"must be {op} {bound}"
    if kind == "value_error":
        return str(ctx.get("error", err["msg"]))
    return err["msg"][0].lower() + err["msg"][1:]


def format_validation_error(source: str, exc: ValidationError) -> str:
    """One line for the first error, naming the field path; more are counted."""
    errors = exc.errors()
    first = errors[0]
    loc = _loc(tuple(first["loc"]))
    msg = _message(first)
    # A model validator reports "field: problem" itself; fold it into the path.
    if first["type"] == "value_error" and re.match(r"^[\w\[\].]+: ", msg):
        sub, _, msg = msg.partition(": ")
        loc = f"{loc}.{sub}" if loc else sub
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    where = f"{loc}: " if loc else ""
    return f"{source}: {where}{msg}{more}"
