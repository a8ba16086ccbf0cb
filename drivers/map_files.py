"""Register maps as files (docs/design.md, "Register-map files"): a map is a TOML file
holding exactly the fields of :class:`drivers.registers.RegisterMap`, so that any
built-in map dumped to TOML loads back identical; the built-in maps beside the
code-defined generic one ship as such files (drivers/maps/); ``[controller]
profile`` names a built-in map or a file, and ``[controller.registers]`` may
still override single entries (:func:`load_map`).

Errors name the file and the entry, e.g. ``acme.toml: registers[3] (TARGET_Y):
type: Input should be 'u16', 'i16', 'u32' or 'i32'``.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from drivers.registers import (
    GENERIC,
    Register,
    RegisterMap,
    RegisterMapError,
)

#: Where the built-in map files live (shipped with the package).
MAPS_DIR = Path(__file__).resolve().parent / "maps"
_OVERRIDE_TABLE = "[controller.registers]"


# --- writing ---------------------------------------------------------------------------


def _string(text: str) -> str:
    """A TOML basic string (multi-line when the text has line breaks)."""
    escaped = text.replace("\\", "\\\\")
    if "\n" in text:
        return '"""\n' + escaped.replace('"""', '""\\"') + '"""'
    escaped = escaped.replace('"', '\\"').replace("\t", "\\t")
    return f'"{escaped}"'


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {value!r} in a register map")


def map_to_toml(register_map: RegisterMap, header: str = "") -> str:
    """``register_map`` as the text of a map file (every field written, defaults
    too: the file says everything the map is)."""
    data = register_map.model_dump()
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    # Top-level keys first: in TOML a key after a [table] header belongs to it.
    for key in ("name", "description", "motion", "offset_convention", "alarm_code",
                "merge_gap"):
        lines.append(f"{key} = {_value(data[key])}")
    for reg in data["registers"]:
        lines += ["", "[[registers]]"]
        lines += [f"{k} = {_value(v)}" for k, v in reg.items() if v is not None]
    for flag, bit in data["status"].items():
        lines += ["", f"[status.{flag}]"] + [f"{k} = {_value(v)}" for k, v in bit.items()]
    lines += ["", "[commands]"]
    lines += [f"{name} = {_value(steps)}" for name, steps in data["commands"].items()]
    if data["unsupported"]:
        lines += ["", "[unsupported]"]
        lines += [f"{k} = {_value(v)}" for k, v in data["unsupported"].items()]
    return "\n".join(lines) + "\n"


# --- reading ---------------------------------------------------------------------------


def map_from_toml(text: str, source: str = "register map") -> RegisterMap:
    """The map in ``text`` (``source``: the file's name, for the messages).
    RegisterMapError naming the file and the entry."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise RegisterMapError(source, f"not valid TOML: {exc}") from None
    try:
        return RegisterMap.model_validate(data)
    except ValidationError as exc:
        raise RegisterMapError(source, _located(data, exc)) from None


def read_map(path: str | Path) -> RegisterMap:
    """The map file at ``path`` (its name in the messages)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise RegisterMapError(p.name, f"cannot read the register map file ({exc.strerror})"
                               ) from None
    return map_from_toml(text, p.name)


def _located(data: Mapping[str, Any], exc: ValidationError) -> str:
    """The first error of ``exc``, its place said as a user reads the file:
    ``registers[3] (TARGET_Y): type: ...``; the map's own checks by themselves."""
    errors = exc.errors()
    # A misspelt field shows as the unknown field and the missing one: name the typo.
    err = next((e for e in errors if e["type"] == "extra_forbidden"), errors[0])
    loc = list(err["loc"])
    msg = str(err["msg"]).removeprefix("Value error, ")
    where = ""
    if len(loc) >= 2 and loc[0] == "registers" and isinstance(loc[1], int):
        regs = data.get("registers") or []
        name = regs[loc[1]].get("name") if loc[1] < len(regs) and isinstance(
            regs[loc[1]], Mapping) else None
        where = f"registers[{loc[1]}]" + (f" ({name})" if name else "")
        loc = loc[2:]
    elif loc:
        where, loc = str(loc[0]), loc[1:]
    rest = ".".join(str(x) for x in loc)
    place = ": ".join(p for p in (where, rest) if p)
    return f"{place}: {msg}" if place else msg


# --- the built-in maps and a profile's map -----------------------------------------------


@cache
def builtin_maps() -> dict[str, RegisterMap]:
    """Every built-in map by name: orthocal-generic (in code) and the files of
    drivers/maps/ (each loaded as a user's file would be)."""
    maps = {GENERIC.name: GENERIC}
    for path in sorted(MAPS_DIR.glob("*.toml")):
        m = read_map(path)
        if m.name in maps:
            raise RegisterMapError(path.name, f"a built-in map named {m.name!r} exists already")
        maps[m.name] = m
    return maps


def is_map_file(profile: str) -> bool:
    """Whether ``profile`` names a map file rather than a built-in map."""
    return profile.endswith(".toml") or "/" in profile or "\\" in profile


def resolve_map(profile: str | RegisterMap, base_dir: str | Path | None = None
                ) -> RegisterMap:
    """The map ``profile`` names: a built-in one, or a file (relative to ``base_dir``,
    the config's folder). RegisterMapError naming it when neither."""
    if isinstance(profile, RegisterMap):
        return profile
    maps = builtin_maps()
    if profile in maps:
        return maps[profile]
    if is_map_file(profile):
        path = Path(profile)
        if not path.is_absolute() and base_dir is not None:
            path = Path(base_dir) / path
        return read_map(path)
    raise RegisterMapError(f"profile {profile!r}", "unknown register map; built-in: "
                           f"{sorted(maps)}, or a .toml file (docs/design.md, Register-map files)")


def load_map(profile: str | RegisterMap = "orthocal-generic",
             overrides: Mapping[str, Mapping[str, Any]] | None = None,
             base_dir: str | Path | None = None) -> RegisterMap:
    """The map ``profile`` names (:func:`resolve_map`) with single-entry
    ``overrides`` applied.

    ``overrides`` is the config table ``[controller.registers]``, e.g.
    ``{"OFFSET_X": {"address": 130}}``: each key names an existing register and
    its value replaces some of that entry's fields. Raises RegisterMapError naming
    the bad entry (unknown profile, unknown register, bad field or value, or a
    result that overlaps another register).
    """
    base = resolve_map(profile, base_dir)
    if not overrides:
        return base
    if not isinstance(overrides, Mapping):
        raise RegisterMapError(_OVERRIDE_TABLE, "must be a table of register name -> fields")
    registers = {r.name: r for r in base.registers}
    for name, fields in overrides.items():
        entry = f"{_OVERRIDE_TABLE} {name}"
        if name not in registers:
            raise RegisterMapError(entry, f"no such register in profile {base.name!r}; "
                                          f"known: {', '.join(registers)}")
        if not isinstance(fields, Mapping):
            raise RegisterMapError(entry, "must be a table of fields, e.g. {address = 130}")
        if "name" in fields and fields["name"] != name:
            raise RegisterMapError(entry, "cannot rename a register")
        merged = registers[name].model_dump() | dict(fields)
        try:
            registers[name] = Register.model_validate(merged)
        except ValidationError as exc:
            raise RegisterMapError(entry, _first_error(exc)) from None
    try:
        return RegisterMap.model_validate(
            base.model_dump() | {"registers": [r.model_dump() for r in registers.values()]}
        )
    except ValidationError as exc:
        raise RegisterMapError(_OVERRIDE_TABLE, _first_error(exc)) from None


def _first_error(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors():
        loc = ".".join(str(x) for x in err["loc"])
        msg = err["msg"].removeprefix("Value error, ")
        parts.append(f"{loc}: {msg}" if loc else msg)
    return "; ".join(parts)
