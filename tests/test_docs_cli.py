"""docs/design.md says what the command line does: every option of every command's
--help is named where design.md describes that command (its own paragraphs, or the
options common to several), and the names of a stroke and a joint coordinate are
defined."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from station.commands.cli import build_parser

DESIGN = (Path(__file__).resolve().parents[1] / "docs" / "design.md").read_text(encoding="utf-8")
PARSER = build_parser()
COMMANDS = next(a for a in PARSER._actions
                if isinstance(a, argparse._SubParsersAction)).choices


def _paragraphs() -> list[str]:
    """design.md cut at blank lines and at list items; a list that a command's paragraph
    ending in ":" introduces stays with it."""
    out: list[str] = []
    for block in DESIGN.split("\n\n"):
        if out and out[-1].startswith("`orthocal") and out[-1].rstrip().endswith(":") \
                and block.startswith("- "):
            out[-1] += "\n\n" + block
        else:
            out += re.split(r"\n(?=- )", block)
    return out


def described(command: str) -> str:
    """Where design.md describes ``command``: the paragraphs that begin with it (a
    list item's or a bold lead's too), and the paragraph of the options common to
    several commands where it names this one."""
    start = re.compile(rf"^(- )?(\*\*[^*]+\*\* )?`orthocal {re.escape(command)}\b")
    mine = [p for p in _paragraphs() if start.match(p)]
    common = [p for p in _paragraphs() if p.startswith("Common options of")
              and (f"`{command}`" in p.split(":")[0] or re.search(r"Every\s+command", p))]
    return "\n".join(mine + common)


def options(command: str) -> list[str]:
    parser = COMMANDS[command]
    return [o for a in parser._actions if a.help != argparse.SUPPRESS
            for o in a.option_strings if o.startswith("--") and o != "--help"]


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_option_is_named_in_the_commands_row(command: str) -> None:
    text = described(command)
    assert text, f"design.md does not describe orthocal {command}"
    missing = [o for o in options(command) if f"`{o}" not in text
               and not re.search(rf"[\[(`| ]{re.escape(o)}\b", text)]
    assert not missing, f"orthocal {command}: {missing} not in design.md"


def test_identify_names_its_geometry_and_the_stands() -> None:
    text = described("identify")
    for option in ("--leg-length", "--rho-min", "--rho-max", "--mount-error"):
        assert f"`{option}" in text


def test_a_stroke_and_a_joint_coordinate_are_two_names() -> None:
    assert "*stroke* s" in DESIGN and "*joint coordinate* ρ_i" in DESIGN
    model = (Path(__file__).resolve().parents[1] / "docs" / "model.md").read_text(
        encoding="utf-8")
    assert "ρmin" not in model and "ρmax" not in model  # a stroke is s, never ρ
