"""report.html in a real browser (Debian's Chromium, headless): drawn again from the
golden run's result.json by ``orthocal report``, it lays out with every figure drawn
at a real size, nothing wider than the page, and prints to PDF, as a shop prints it.

The layout facts come from the browser itself: a copy of the page carries a script
that measures it after load and writes what it found into the DOM, which Chromium's
``--dump-dom`` prints. Chromium is started with a fresh profile and without the
background networking a closed network refuses, and is stopped with its whole
process group, so nothing is left behind."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
from browser import browse, chromium
from builders import cli
from result_builders import golden_result
from system import require

GOLDEN = Path(__file__).parents[2] / "data" / "golden_run"
#: What the page says of itself once laid out: every figure's box, how wide the
#: document scrolls against the window, the headings in order.
PROBE = """<script>
window.addEventListener("load", () => {
  const figures = [...document.querySelectorAll("svg")].map(s => {
    const r = s.getBoundingClientRect(); return [r.width, r.height]; });
  const page = document.documentElement.clientWidth;
  const widest = document.documentElement.scrollWidth;
  const headings = [...document.querySelectorAll("h1, h2")].map(h => h.textContent);
  const out = document.createElement("pre"); out.id = "orthocal-probe";
  out.textContent = JSON.stringify({figures, page, widest, headings});
  document.body.appendChild(out);
});
</script>"""


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The golden run's report.html, drawn by this code, figures included."""
    require(chromium() is not None, "Chromium (Debian's chromium package)")
    run = tmp_path_factory.mktemp("run") / "golden"
    shutil.copytree(GOLDEN, run)
    (run / "report.html").unlink()
    # the golden result.json lacks what cannot repeat (times, the run directory)
    (run / "result.json").write_text(json.dumps(golden_result()), encoding="utf-8")
    done = cli("report", str(run), cwd=run)
    assert done.returncode == 0, done.stderr
    return run / "report.html"


def test_every_figure_is_drawn_and_nothing_is_wider_than_the_page(report, tmp_path) -> None:
    page = tmp_path / "probed.html"
    page.write_text(report.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"),
                    encoding="utf-8")
    dom = browse(tmp_path, "--dump-dom", page.as_uri())
    m = re.search(r'<pre id="orthocal-probe">(.*?)</pre>', dom, re.S)
    assert m, "the page's script did not run"
    facts = json.loads(m.group(1).replace("&quot;", '"').replace("&amp;", "&"))
    assert len(facts["figures"]) == report.read_text(encoding="utf-8").count("<svg")
    assert facts["figures"] and all(w > 200 and h > 100 for w, h in facts["figures"])
    assert facts["widest"] <= facts["page"] + 1  # no sideways scrolling on a screen
    assert facts["headings"][0].startswith("Calibration report")
    assert "Accuracy at the tool" in facts["headings"]


#: A4 in PDF points (210 × 297 mm), and what a sheet may exceed it by in rounding.
A4_PT, SLACK_PT = (595.28, 841.89), 1.0


def test_it_prints_to_a4_with_the_verdict_and_the_result_table_on_page_one(report, tmp_path
                                                                          ) -> None:
    require(_has_pypdf(), "pypdf (pyproject.toml's test extra)")
    from pypdf import PdfReader

    pdf = tmp_path / "report.pdf"
    browse(tmp_path, "--no-pdf-header-footer", f"--print-to-pdf={pdf}", report.as_uri())
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF-")
    assert len(data) > 50_000  # the figures are in it, as vectors
    pages = PdfReader(pdf).pages
    assert len(pages) >= 2  # the whole report, not a blank first sheet
    for page in pages:  # the print stylesheet's @page size: every sheet A4, none wider
        box = page.mediabox
        assert float(box.width) <= A4_PT[0] + SLACK_PT
        assert float(box.height) <= A4_PT[1] + SLACK_PT
        assert float(box.width) >= A4_PT[0] - SLACK_PT  # A4, not Letter's 612 pt
    first = " ".join(pages[0].extract_text().split())
    result = golden_result()
    assert "Completed" in first  # the verdict's badge ("Calibration report … Completed")
    assert "as found" in first and "as left" in first
    # every joint's row of the table, its figures as printed (mm, U+2212)
    for axis in "xyz":
        left = report_number(result["offsets_final"][axis])
        assert f"joint {axis}" in first and left in first, (axis, left, first[:600])


def report_number(mm: float) -> str:
    """An offset as the as found / as left table prints it: mm to 4 decimals, signed,
    the minus sign U+2212."""
    return f"{mm:+.4f}".replace("-", "\u2212")


def _has_pypdf() -> bool:
    try:
        import pypdf  # noqa: F401
    except ImportError:
        return False
    return True
