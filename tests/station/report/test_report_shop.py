"""report.html and the summary for the shop floor: the operator's result (the
offsets as found → as left) first, one unit per table said in its header, one
minus sign (U+2212) in every number, degrees of freedom and coverage factors said
once and readably, and who calibrated with which gauges."""

from __future__ import annotations

import html
import re

import pytest
from result_builders import golden_result

from station import report
from station.record.io import parse_result
from station.record.quantity_text import interval, plus_minus, um
from station.report.format import dof_text, k_text, minus_signs, minus_signs_html

#: A number's ASCII hyphen-minus: one not after a letter, digit, dot, hyphen or slash
#: (dates 2024-05-02, ISO 230-2, file names and options keep theirs).
HYPHEN_NUMBER = re.compile(r"(?<![\w.\-/])-(?=\.?\d)")
UNIT = re.compile(r"\((µm|mm|mm/m|mrad)\b[^)]*\)")


def _page() -> str:
    return report.render_html(golden_result(), figures=False)


def _text(page: str) -> str:
    """The page's words: no figures, stylesheet, code or tags, entities decoded."""
    page = re.sub(r"<(svg|style|code|script)\b.*?</\1>", " ", page, flags=re.S)
    return html.unescape(re.sub(r"<[^>]*>", " ", page))


def _tables(page: str) -> list[str]:
    return re.findall(r"<table\b.*?</table>", page, flags=re.S)


def test_the_as_found_as_left_table_is_the_first_section() -> None:
    page, result = _page(), golden_result()
    # after the first screen's block (station.report.first_screen), the first section
    glance = page.index('id="first-screen"')
    first = page.index("<h2", page.index("</section>", glance))
    assert page[first:].startswith('<h2 id="as-left">')
    assert "as found → as left" in page[first:page.index("</h2>", first)]
    assert first < page.index("What was done") < page.index("Accuracy at the tool")
    table = _tables(page[first:])[0]
    rows = re.findall(r"<tr><td class=\"l\">joint ([xyz])</td>(.*?)</tr>", table)
    assert [axis for axis, _ in rows] == ["x", "y", "z"]
    for axis, cells in rows:
        found = result["offsets_before"][axis]
        left = result["offsets_final"][axis]
        shown = re.findall(r'<td class="num">(.*?)</td>', cells)
        # as found, as left, the change: mm to 0.1 µm, the minus sign U+2212
        assert [float(c.replace("−", "-")) for c in shown] == pytest.approx(
            [found, left, left - found], abs=5e-5)
    assert "offsets in mm" in table
    # the bottom of the page holds it no more
    assert page.count("as found → as left") == 1


def test_each_table_says_one_unit_in_its_header_and_none_in_its_cells() -> None:
    for table in _tables(_page()):
        if "class='cert'" in table:  # the certificate: a unit with each figure
            continue
        if re.match(r"<table class=[\"']stated[\"']", table):
            # the statement's quantities, each with its unit (quantity_text's one way):
            # every figure with a unit is one of them
            _stated_cells(table)
            continue
        head = re.search(r"<tr>(.*?)</tr>", table, flags=re.S)
        assert head is not None
        units = {m.group(1) for m in UNIT.finditer(html.unescape(head.group(1)))}
        assert len(units) <= 1, (units, table[:300])
        for cell in re.findall(r'<td class=["\']num["\'][^>]*>(.*?)</td>', table):
            assert not re.search(r"\d\s*(µm|mm)\b", cell), (cell, table[:200])


def _stated_cells(table: str) -> None:
    """Every cell of a table of the statement's quantities that holds a unit is one of
    them as quantity_text prints it (its value ± U, its interval, or its figure)."""
    said = set()
    for q in parse_result(golden_result()).statement or []:
        said |= {plus_minus(q), interval(q), f"{um(q.value)} µm"}
    # (a simulated machine's hidden value, its own column, is a value alone)
    cells = [html.unescape(re.sub(r"<[^>]*>", "", c)).replace("−", "-") for c in
             re.findall(r'<td class=["\']num["\'][^>]*>(.*?)</td>', table)]
    truths = re.findall(r'<td class="num truth">(.*?)</td>', table)
    assert all("±" not in t for t in truths)
    with_unit = [c for c in cells if re.search(r"\d\s*(µm|mm|mm/m|mrad)\b", c)]
    assert with_unit, table[:200]
    assert all(c in said for c in with_unit), [c for c in with_unit if c not in said]


def test_no_wall_of_zero_millimetres_and_no_false_footer() -> None:
    text = _text(_page())
    assert not re.search(r"(?<![\d.])[+−]?0\.0+ mm\b", text)
    assert "All lengths in millimetres" not in text
    assert "Each table states its unit in its header" in text


def test_every_number_has_the_one_minus_sign() -> None:
    page = _page()
    bad = HYPHEN_NUMBER.findall(_text(page))
    assert not bad, re.findall(r".{30}(?<![\w.\-/])-(?=\.?\d).{10}", _text(page))[:5]
    for table in _tables(page):
        for cell in re.findall(r"<td[^>]*>(.*?)</td>", table, flags=re.S):
            assert not HYPHEN_NUMBER.search(_text(cell)), cell
    # the golden run has negative numbers in every kind of place, so this says something
    assert _text(page).count("−") > 40
    summary = report.summary_text(golden_result()).splitlines()
    assert not [ln for ln in summary[:-1] if HYPHEN_NUMBER.search(ln)]
    assert sum(ln.count("−") for ln in summary) > 5


def test_the_minus_sign_leaves_dates_standards_files_and_code_alone() -> None:
    assert minus_signs("x -1.101, y -.5 mm") == "x −1.101, y −.5 mm"
    kept = "2024-05-02, ISO 230-2, run-3/-1.csv, --seed 5, a-1"
    assert minus_signs(kept) == kept
    page = '<p>e -2 µm</p><code>rho_min = -100</code><svg><text>-3</text></svg>'
    assert minus_signs_html(page) == (
        '<p>e −2 µm</p><code>rho_min = -100</code><svg><text>-3</text></svg>')


def test_degrees_of_freedom_and_coverage_factors_are_said_once() -> None:
    assert dof_text(None) == "∞" and dof_text(321746.7) == "∞" and dof_text(1000.5) == "∞"
    assert dof_text(999.0) == "999.0" and dof_text(14.0111) == "14.0"
    assert k_text([1.9599, 1.96, 1.96004]) == "1.96"
    assert k_text([2.14, 2.03]) == "2.03–2.14" and k_text([]) == "—"
    text = _text(_page())
    assert "effective degrees of freedom" in text
    dof_row = re.search(r"effective degrees of freedom(.*?)coverage", text, flags=re.S)
    budget = golden_result()["uncertainty_budget"]
    expected = [dof_text(budget["effective_dof"][f"drho_{a}"]) for a in "xyz"]
    assert dof_row is not None and dof_row.group(1).split() == expected
    summary = report.summary_text(golden_result())
    ks = [budget["coverage_factor"][f"drho_{a}"] for a in "xyz"]
    assert "k = 1.96–1.96" not in summary and f"95 %, k = {k_text(ks)}, " in summary


def test_the_operator_and_the_gauges_are_in_the_header() -> None:
    page = _page()
    assert "<dt>operator</dt><dd>not given</dd>" in page
    assert "not recorded by the station" not in page
    named = {**golden_result(), "operator": "J. Smith <QA>",
             "gauges": [{"name": "A", "protocol": "mitutoyo", "serial": "SN-0042"},
                        {"name": "B", "protocol": "sylvac", "serial": None}]}
    page = report.render_html(named, figures=False)
    assert "<dt>operator</dt><dd>J. Smith &lt;QA&gt;</dd>" in page
    assert ("<dt>gauges</dt><dd>A: mitutoyo, serial SN-0042; B: sylvac, serial "
            "not given</dd>") in page
    assert page.index("<dt>operator</dt>") < page.index("What was done")
