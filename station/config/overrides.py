"""A config section's overrides: some of its keys, each of the section's own type, no
other key (a simulated run's ``[procedure]``, ``[writeback]``, ``[report]`` and
``[uncertainty]``, which
the journal header keeps with the simulation). Nothing absent is filled in: the keys
given are the keys kept, read back with ``model_dump(exclude_unset=True)``.

The models are made from the sections' fields, so a key added to a section is one
its overrides take. To a type checker they are the sections themselves."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, create_model

from station.config import ProcedureConfig, ReportConfig, UncertaintyConfig, WritebackConfig


def overrides_of(section: type[BaseModel]) -> type[BaseModel]:
    """The model of ``section``'s overrides: every field optional, its constraints kept."""
    fields: dict[str, Any] = {
        name: (_constrained(info.annotation, info.metadata) | None,
               Field(None, description=info.description))
        for name, info in section.model_fields.items()}
    return create_model(section.__name__.replace("Config", "Overrides"),
                        __config__=ConfigDict(extra="forbid"), **fields)


def _constrained(annotation: Any, metadata: list[Any]) -> Any:
    """``annotation`` with its field's constraints (gt, le, min_length, …)."""
    return Annotated[(annotation, *metadata)] if metadata else annotation


if TYPE_CHECKING:
    ProcedureOverrides = ProcedureConfig
    WritebackOverrides = WritebackConfig
    ReportOverrides = ReportConfig
    UncertaintyOverrides = UncertaintyConfig
else:
    ProcedureOverrides = overrides_of(ProcedureConfig)
    WritebackOverrides = overrides_of(WritebackConfig)
    ReportOverrides = overrides_of(ReportConfig)
    UncertaintyOverrides = overrides_of(UncertaintyConfig)
