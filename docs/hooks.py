"""MkDocs hooks (mkdocs.yml): the repo's files that the pages link to but that live
outside docs/, added to the site as they are in the repo, so that a link to them is
checked like any other and the built site holds them: BENCHMARKS.md (a page, under its
own name), the JSON Schemas the package ships (schemas/), and examples/."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files


def repo_files(root: Path) -> Iterator[tuple[Path, str]]:
    """(the file in the repo at ``root``, its path in the site)."""
    yield root / "BENCHMARKS.md", "BENCHMARKS.md"
    for path in sorted((root / "station" / "record" / "schemas").glob("*.schema.json")):
        yield path, f"schemas/{path.name}"
    for path in sorted((root / "examples").rglob("*")):
        if path.is_file():
            yield path, path.relative_to(root).as_posix()


def on_files(files: Files, config: MkDocsConfig) -> Files:
    root = Path(config.config_file_path).resolve().parent  # the repo: mkdocs.yml's folder
    for path, uri in repo_files(root):
        files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files
