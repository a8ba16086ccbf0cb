"""The mounting pictures on disk: one SVG per setup (station.report.mounting_picture),
written into a run directory before anything moves (``orthocal run``, and the folder
``orthocal run --plan`` names), read back into report.html.

A picture is a function of the config and the checked plan, written once per run
directory: a resumed run keeps what its operator was shown and only draws what is
missing (a run directory from before the pictures existed)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from html import escape
from pathlib import Path

from drivers.files import write_atomic
from station.plan.mounting import MountingSheet
from station.report.mounting_picture import draw

#: mounting-1-leg-x.svg: the setup's number (1-based) and its leg.
PICTURE = re.compile(r"^mounting-(\d+)-leg-([xyz])\.svg$")


def write_pictures(directory: Path, sheets: Sequence[MountingSheet], *,
                   missing_only: bool = False) -> list[Path]:
    """Each sheet's picture into ``directory`` (sheet.file_name), atomically; with
    ``missing_only`` those already there are left as they are. Returns every
    sheet's path. OSError (an unwritable folder, a full disk) is the caller's to
    word."""
    paths = []
    for sheet in sheets:
        path = Path(directory) / sheet.file_name
        if not (missing_only and path.exists()):
            write_atomic(path, draw(sheet))
        paths.append(path)
    return paths


def pictures_in(run_dir: Path | str | None) -> list[tuple[str, str]]:
    """The mounting pictures a run directory holds, as (file name, SVG text) in the
    order of their setups; none where there is no such directory or file."""
    if run_dir is None or not Path(run_dir).is_dir():
        return []
    found = []
    for path in Path(run_dir).iterdir():
        m = PICTURE.match(path.name)
        if m is None:
            continue
        try:
            found.append((int(m.group(1)), path.name, path.read_text(encoding="utf-8")))
        except (OSError, UnicodeDecodeError):
            continue  # a picture that cannot be read costs the report only itself
    return [(name, svg) for _, name, svg in sorted(found)]


def figures_html(pictures: Sequence[tuple[str, str]]) -> str:
    """report.html's section of the mounting pictures ("" without any): each inline,
    named by its file, as the operator was shown it at the mounting."""
    if not pictures:
        return ""
    figures = "".join(
        f'<figure class="mounting">{_inline(svg)}<figcaption>{escape(name)}</figcaption>'
        "</figure>" for name, svg in pictures)
    return ("<h2>Mountings</h2>\n<p>Each setup's mounting as the prompt named it: the stand "
            "at the gauge plane within its tolerance, each plunger's face, the way the leg "
            "moves for a positive reading, and the preload window the plan check "
            f"allows.</p>\n{figures}")


def without_pictures(page: str) -> str:
    """report.html's text less its mounting pictures: what is left of it without them
    (whether it has its figures, station.commands.report)."""
    return MOUNTING_FIGURE.sub("", page)


MOUNTING_FIGURE = re.compile(r'<figure class="mounting">.*?</figure>', re.S)


def _inline(svg: str) -> str:
    """An SVG document as inline markup: from its ``<svg`` on (no XML declaration)."""
    start = svg.find("<svg")
    return svg[start:].strip() if start >= 0 else ""
