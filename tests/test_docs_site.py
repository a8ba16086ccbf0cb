"""The docs a newcomer reads: a README short enough to read (what it is, the quick start
that CI runs, the commands, bring-up, links), and the site built from docs/ with
mkdocs.yml, where a broken link or anchor, or a page left out of the nav, fails the build;
the config reference generated from the config's models and current; and every citation
of a section of the README or of a page of the site naming a heading it has."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from station.config import reference

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = (ROOT / "README.md").read_text(encoding="utf-8")


def build(root: Path, site: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site),
         "--config-file", str(root / "mkdocs.yml")],
        cwd=root, capture_output=True, text=True, timeout=60, check=False)


def test_the_readme_is_short_and_its_tables_fit_a_screen() -> None:
    lines = README.splitlines()
    assert 40 < len(lines) <= 250, len(lines)
    wide = [line for line in lines if line.startswith("|") and len(line) > 120]
    assert not wide, wide


def test_the_readme_quick_start_is_what_ci_runs() -> None:
    # .ci/run installs "as the README says" and runs "the README's test command": the
    # two must say the same commands, word for word.
    block = re.search(r"## Quick start\n.*?```sh\n(.*?)```", README, re.S)
    assert block, "the README has no quick start block"
    assert block.group(1).splitlines() == [
        'pip install -e ".[test]" && orthocal run --simulate', "python -m pytest -q"]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    commands = [line.strip() for line in ci.splitlines() if not line.lstrip().startswith("#")]
    assert 'pip install -e ".[test]"' in commands
    assert "python -m pytest -q" in commands
    assert any(c.startswith("orthocal run --simulate") for c in commands)
    assert any(c.startswith("mkdocs build --strict --site-dir") for c in commands)


def nav_pages(nav: list) -> list[str]:
    out: list[str] = []
    for entry in nav:
        value = next(iter(entry.values())) if isinstance(entry, dict) else entry
        out += nav_pages(value) if isinstance(value, list) else [value]
    return out


def test_every_page_of_docs_is_in_the_nav_and_every_entry_is_a_page() -> None:
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    pages = nav_pages(config["nav"])
    here = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md"))
    # BENCHMARKS.md is the repo's own, added to the site by docs/hooks.py.
    assert sorted(p for p in pages if p != "BENCHMARKS.md") == here
    assert {"design.md", "model.md", "config-reference.md", "BENCHMARKS.md"} <= set(pages)
    assert len(pages) == len(set(pages))


def test_the_site_builds_with_warnings_as_errors(tmp_path: Path) -> None:
    run = build(ROOT, tmp_path / "site")
    assert run.returncode == 0, run.stderr
    site = tmp_path / "site"
    for page in ("index.html", "quick-start.html", "config-reference.html", "design.html",
                 "model.html", "BENCHMARKS.html", "schemas/result.schema.json",
                 "examples/rehearsal.toml"):
        assert (site / page).is_file(), page
    assert "Every key of the station config" in (site / "config-reference.html").read_text(
        encoding="utf-8")


def test_a_broken_link_or_anchor_fails_the_build(tmp_path: Path) -> None:
    # The check itself, on a copy of the site's sources: a link to a heading that does
    # not exist and a page left out of the nav each fail the build, named.
    copy = tmp_path / "repo"
    copy.mkdir()
    shutil.copy(ROOT / "mkdocs.yml", copy)
    shutil.copytree(DOCS, copy / "docs", ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("BENCHMARKS.md", "station", "examples"):
        (copy / name).symlink_to(ROOT / name)
    with (copy / "docs" / "results.md").open("a", encoding="utf-8") as page:
        page.write("\n[a section](design.md#no-such-section)\n")
    (copy / "docs" / "stray").with_suffix(".md").write_text("# Stray\n", encoding="utf-8")
    run = build(copy, tmp_path / "site")
    assert run.returncode == 1
    assert "design.md#no-such-section" in run.stderr
    assert re.search(r"not included in the \"nav\".*\n\s*- stray\.md", run.stderr), run.stderr


def test_the_config_reference_is_current() -> None:
    page = (DOCS / "config-reference.md").read_text(encoding="utf-8")
    assert page == reference.markdown(), (
        "docs/config-reference.md is stale: python -m station.config.reference > "
        "docs/config-reference.md")


def test_every_config_key_has_a_meaning_and_every_meaning_a_key() -> None:
    keys = reference.keys()
    assert {"machine.leg_length", "indicators.port", "setups.at", "acceptance.tool_rms_um"} \
        <= set(keys)
    missing = [k for k in keys if not reference.meaning(*k.rsplit(".", 1), _field(k))]
    assert not missing, f"no meaning in station/config/reference.py MEANINGS: {missing}"
    stale = sorted(set(reference.MEANINGS) - set(keys))
    assert not stale, f"MEANINGS names keys the config does not have: {stale}"


def _field(key: str):  # the FieldInfo of "table.key" ("joints.reference.kind": a sub-table's)
    table, name = key.rsplit(".", 1)
    model = next(m for t, _, m in reference.tables() if t == table)
    return model.model_fields[name]


def test_the_reference_says_what_pydantic_checks() -> None:
    page = reference.markdown()
    rows = {line.split("|")[1].strip(): line for line in page.splitlines()
            if line.startswith("| `")}
    assert "≥ 0, ≤ 247" in rows["`device_id`"] and "| `1` |" in rows["`device_id`"]
    assert '`"mitutoyo"` or `"sylvac"` or `"mahr"` or `"generic"`' in rows["`protocol`"]
    assert "| required |" in rows["`leg`"]
    assert "> 0.05, < 0.95" in rows["`at`"] and "| `0.5` |" in rows["`at`"]
    assert "## `[[indicators]]`" in page and "## `[procedure]`" in page


def test_design_md_lists_every_config_key() -> None:
    # design.md's "Station config" is the contract: every key the models accept is there.
    design = (DOCS / "design.md").read_text(encoding="utf-8")
    section = design.split("### Station config", 1)[1].split("\n### ", 1)[0]
    missing = [k for k in reference.keys()
               if not re.search(rf"\b{re.escape(k.rsplit('.', 1)[1])}\b", section)]
    assert not missing, f"docs/design.md, \"Station config\" does not name {missing}"


def headings(path: Path) -> set[str]:
    return {re.sub(r"^#+\s*", "", line).strip().strip("`")
            for line in path.read_text(encoding="utf-8").splitlines()
            if re.match(r"#{1,6} ", line)}


# "README "Models"", "docs/drive.md, "Your drive"", "docs/method.md's "Models"": a section
# of the README or of a page of the site (design.md and model.md, the contracts, cite
# theirs by their own tests).
CITATION = re.compile(r"\b(README|docs/(?!design\.md|model\.md)[\w-]+\.md)(?:'s)?,?\s+\"([^\"]+)\"")


@pytest.mark.parametrize("folder", ["orthocal", "drivers", "station", "bench", "tests",
                                    "examples", "docs"])
def test_every_cited_section_is_a_heading_of_its_page(folder: str) -> None:
    texts = [p for p in sorted((ROOT / folder).rglob("*")) if p.is_file()
             and p.suffix in (".py", ".md", ".toml") and p != Path(__file__).resolve()]
    if folder == "docs":
        texts += [ROOT / "README.md", ROOT / "BENCHMARKS.md"]
    bad = []
    for path in texts:
        for m in CITATION.finditer(path.read_text(encoding="utf-8")):
            page = ROOT / ("README.md" if m.group(1) == "README" else m.group(1))
            title = " ".join(m.group(2).split())
            if not page.is_file() or title not in headings(page):
                bad.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    assert not bad, bad
