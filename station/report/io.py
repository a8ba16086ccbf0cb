"""The run's result document on disk: result.json, written atomically, in the
schema's key order, NaN and infinities as null."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from drivers.files import write_atomic
from station.report.format import dev_keys

# Key order of result.json: the schema's order, so that a person opening the file
# finds status and identified values at the top, not buried alphabetically.
_TOP_ORDER = (
    "schema_version", "run_dir", "status", "message", "started", "finished", "duration_s",
    "simulated", "simulation", "machine", "model", "method", "model_selection", "identified",
    "std_errors", "correlation", "residual_rms_mm", "sigma_mm", "condition_number", "noise_mm",
    "fit_ok", "fit_note",
    "deviations", "deviations_rms_mm", "setups", "stands", "offsets_before", "offsets_written",
    "writeback", "verification", "iterations", "converged", "loop", "remaining", "accuracy",
    "timing",
)


# --------------------------------------------------------------------------- json


def jsonable_value(value: Any) -> Any:
    """Plain JSON types; NaN/inf become None because json.dumps would emit the
    invalid tokens NaN/Infinity that strict parsers (jq, JavaScript) reject."""
    if isinstance(value, Mapping):
        return {str(k): jsonable_value(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable_value(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, str | int):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    # numpy scalars and arrays come from the identification; no numpy import needed.
    if hasattr(value, "tolist"):
        return jsonable_value(value.tolist())
    if hasattr(value, "isoformat"):
        return value.isoformat()
    raise TypeError(f"result field of type {type(value).__name__} is not JSON-serialisable")


def jsonable(result: Mapping[str, Any]) -> dict[str, Any]:
    """The result as written to result.json (schema key order, NaN → None), for
    callers that print it, e.g. ``--json``, so stdout and the file agree."""
    return jsonable_value(_ordered(result))


def _ordered(result: Mapping[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key in _TOP_ORDER:
        if key in result:
            out[key] = result[key]
    for key in sorted(k for k in result if k not in out):
        out[key] = result[key]
    for section in (out, out.get("verification")):
        if isinstance(section, dict) and isinstance(section.get("deviations"), dict):
            devs = section["deviations"]
            section["deviations"] = {k: devs[k] for k in dev_keys(devs)}
    return out


def write_result(result: dict, run_dir: Path) -> Path:
    """Write ``run_dir/result.json`` atomically; NaN and infinities become null."""
    path = Path(run_dir) / "result.json"
    data = jsonable(result)
    write_atomic(path, json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False) + "\n")
    return path
