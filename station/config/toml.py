"""The station config written as TOML: the run directory keeps the config it ran with."""

from __future__ import annotations

import re
from typing import Any

from station.config import StationConfig


def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') \
            .replace("\n", "\\n").replace("\r", "\\r") + '"'
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else toml_value(key)


def toml_text(data: dict[str, Any], header: str = "") -> str:
    """A config-shaped dict as TOML, with ``header`` as leading comment lines.

    Not validated: tests write deliberately broken configs with it. Sections
    missing from ``data`` are left out.
    """
    lines: list[str] = [f"# {line}" for line in header.splitlines()]
    if lines:
        lines.append("")

    def table(name: str, values: dict[str, Any]) -> None:
        lines.append(name)
        subtables = {}
        for k, v in values.items():
            if isinstance(v, dict) and name == "[controller]":
                subtables[k] = v
                continue
            lines.append(f"{_key(k)} = {toml_value(v)}")
        for k, v in subtables.items():
            lines.append("")
            lines.append(f"[controller.{k}]")
            lines.extend(f"{_key(a)} = {toml_value(b)}" for a, b in v.items())
        lines.append("")

    if data.get("station"):  # an empty [station] (no operator named) is left out
        table("[station]", data["station"])
    for section in ("machine", "controller"):
        if data.get(section) is not None:
            table(f"[{section}]", data[section])
    for array in ("indicators", "setups"):
        for item in data.get(array) or ():
            table(f"[[{array}]]", item)
    for section in ("procedure", "writeback", "uncertainty", "joints", "history", "report"):
        # an empty [uncertainty] (every input at its default) and [joints] (no test
        # given) are left out
        values = data.get(section)
        if values is not None and (section not in ("uncertainty", "joints") or any(
                v not in ({}, None) for v in values.values())):
            table(f"[{section}]", values)
    return "\n".join(lines)


def dump_toml(config: StationConfig, header: str = "") -> str:
    """The config as TOML that ``load_config`` reads back to an equal config."""
    return toml_text(config.model_dump(exclude_none=True), header)
