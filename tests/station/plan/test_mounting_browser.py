"""The mounting pictures of a run in a real browser (Debian's Chromium, headless), as
the operator opens them: each SVG the run drew is rendered to PNG and is not blank
(ink in each of its three parts, the touched bar in its colour), its gauges are
named in the SVG as laid out (a probe script writes the drawn texts and their boxes
into the DOM, which ``--dump-dom`` prints), and report.html lays each out at a real
size (docs/design.md, "Mounting pictures")."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from browser import browse, chromium
from builders import FAST
from fakes import FakeRig, fake_config, run_on
from system import require

#: What a page says of its SVGs once laid out: each one's box and, per text drawn, its
#: words, its gauge (data-gauge) and its laid-out width.
PROBE = """<script>
window.addEventListener("load", () => {
  const svgs = [...document.querySelectorAll("svg[data-leg]")].map(s => {
    const r = s.getBoundingClientRect();
    const texts = [...s.querySelectorAll("text")].map(t => [t.textContent,
      t.getAttribute("data-gauge"), t.getAttribute("data-part"), t.getBBox().width]);
    return {leg: s.getAttribute("data-leg"), box: [r.width, r.height], texts};
  });
  const out = document.createElement("pre"); out.id = "orthocal-probe";
  out.textContent = JSON.stringify(svgs);
  document.body.appendChild(out);
});
</script>"""

INK = 60  # a channel this far from the background's is ink
BAR_RGB = (0x1F, 0x4E, 0x79)  # the touched bar (station.report.mounting_picture.BAR)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """A short run on the fakes (builders.BASE: gauge B reversed on leg y): its record,
    its run directory holding the pictures and report.html."""
    require(chromium() is not None, "Chromium (Debian's chromium package)")
    rig = FakeRig(true_drho=(0.4, -0.3, 0.2))
    code, result = run_on(rig, tmp_path_factory.mktemp("runs"), fake_config(**FAST))
    assert code == 0, result.get("message")
    return result


def _probe(tmp: Path, page: Path) -> list[dict[str, Any]]:
    dom = browse(tmp, "--dump-dom", page.as_uri())
    m = re.search(r'<pre id="orthocal-probe">(.*?)</pre>', dom, re.S)
    assert m, "the page's script did not run"
    return json.loads(m.group(1).replace("&quot;", '"').replace("&amp;", "&")
                      .replace("&lt;", "<").replace("&gt;", ">"))


def _gauges(result: dict[str, Any]) -> dict[str, list[str]]:
    """Each leg's gauges, as the run's record lists its setups."""
    return {s["leg"]: list(s["indicators"]) for s in result["setups"]}


def test_each_picture_renders_not_blank_with_its_gauges_named(run, tmp_path) -> None:
    from PIL import Image

    run_dir = Path(run["run_dir"])
    pictures = sorted(run_dir.glob("mounting-*.svg"))
    assert [p.name for p in pictures] == ["mounting-1-leg-x.svg", "mounting-2-leg-y.svg",
                                          "mounting-3-leg-z.svg"]
    gauges = _gauges(run)
    for svg in pictures:
        text = svg.read_text(encoding="utf-8")
        width, height = (int(v) for v in re.search(r'width="(\d+)" height="(\d+)"',
                                                   text).groups())
        png = tmp_path / f"{svg.stem}.png"
        browse(tmp_path, "--hide-scrollbars", f"--window-size={width},{height}",
               f"--screenshot={png}", svg.as_uri())
        image = Image.open(png).convert("RGB")
        assert image.size == (width, height)
        pixels = image.load()
        assert pixels is not None
        background = max(image.getcolors(width * height) or [], key=lambda c: c[0])[1]

        def ink(box: tuple[int, int, int, int], pixels: Any = pixels,
                background: tuple[int, int, int] = background) -> int:
            x0, y0, x1, y1 = box
            return sum(1 for x in range(x0, x1, 2) for y in range(y0, y1, 2)
                       if max(abs(a - b) for a, b in zip(pixels[x, y], background,
                                                         strict=True)) > INK)

        # ink in the side view, the section and the gauges' rows; a blank one has none
        for part in ((20, 120, 560, 440), (580, 120, 940, 440), (20, 470, 940, height)):
            assert ink(part) > 300, (svg.name, part)
        bar = sum(1 for x in range(0, width, 2) for y in range(0, height, 2)
                  if max(abs(a - b) for a, b in zip(pixels[x, y], BAR_RGB, strict=True)) < 30)
        assert bar > 300, svg.name  # the touched bar, both views, in its colour
    # the gauges, named in each picture as the browser lays it out (one page of all)
    page = tmp_path / "pictures.html"
    page.write_text('<!DOCTYPE html><html><head><meta charset="utf-8"></head><body>'
                    + "".join(p.read_text(encoding="utf-8") for p in pictures)
                    + PROBE + "</body></html>", encoding="utf-8")
    drawn = _probe(tmp_path, page)
    assert [d["leg"] for d in drawn] == ["x", "y", "z"]
    for d in drawn:
        assert d["box"][0] == 960 and d["box"][1] > 600  # at its own size
        names = {t[0] for t in d["texts"] if t[2] == "name" and t[3] > 5}
        assert names == set(gauges[d["leg"]]), (d["leg"], names)
        words = " ".join(t[0] for t in d["texts"])
        for name in gauges[d["leg"]]:
            assert f"{name}: push in " in words
    # the reversed mount of leg y, said as drawn
    assert any("B: along \u2212z (a reversed mount)" == t[0] for t in drawn[1]["texts"])


def test_the_report_lays_out_every_mounting_picture(run, tmp_path) -> None:
    report = Path(run["run_dir"]) / "report.html"
    page = tmp_path / "report.html"
    page.write_text(report.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"),
                    encoding="utf-8")
    drawn = _probe(tmp_path, page)
    gauges = _gauges(run)
    assert [d["leg"] for d in drawn] == ["x", "y", "z"]
    for d in drawn:
        w, h = d["box"]
        assert 600 < w <= 1000 and h > 0.6 * w  # scaled to the page, not squashed
        names = {t[0] for t in d["texts"] if t[2] == "name" and t[3] > 3}
        assert names == set(gauges[d["leg"]])
