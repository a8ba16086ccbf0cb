"""One statement of the machine (docs/design.md, "The statement of the machine"): a run's
first screen and its ``--verbose`` details print every ± of a joint's Δρ, a tilt, a gap,
a squareness and the tool as the statement's ``expanded`` (to the digits printed),
every "to do" line is one of ``advice``'s texts, no two pieces of advice contradict, and
the loop's verdict agrees with the statement's decisions. report.html the same, its
figures included, read from its source and as a real browser (headless Chromium) lays it
out for its reader: no "1σ", "3σ" or "std err", every ± and every interval one of the
statement's, every quantity and every advice text in it."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path
from typing import Any

import pytest
from browser import browse, chromium
from fakes import FakeRig, fake_config, run_on
from system import require

from station.history.compare import change_lines, compare
from station.history.controller_terms import csv_lines, linuxcnc
from station.history.entry import entry_of
from station.history.linuxcnc_kins import geometry_hal
from station.history.trend import series
from station.history.twincat import twincat
from station.record.exportable import HEADER
from station.record.identified import identified_machine
from station.record.io import parse_result
from station.record.quantity_text import figure, interval, plus_minus
from station.record.result import RunResult
from station.report.html import render_html
from station.report.text import summary_text

GAPS = (0.15, -0.10, 0.12)
TILTS = (0.2, 0.1, -0.15)
#: "±" and what follows it, as a view prints it: a number and its unit.
PM = re.compile(r"± (\d+(?:\.\d+)?) (µm|mm/m|mrad|µm/m)")


def _run(out: Path, **machine: Any) -> RunResult:
    rig = FakeRig(**{"seed": 12, "noise_mm": 0.001, "mount_error_mm": 5.0,
                     "true_drho": (0.6, -0.4, 0.9), **machine})
    config = fake_config(uncertainty={"leg_straightness_mm": 0.0005,
                                      "temperature_change_c": 0.1},
                         settle_s=0.0, cycles=3)
    code, doc = run_on(rig, out, config)
    assert code in (0, 3), doc.get("message")
    return parse_result(doc)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, RunResult]:
    out = tmp_path_factory.mktemp("statement")
    return {"gapped": _run(out / "gapped", true_gap=GAPS, backlash=(0.0, 0.0, 0.004)),
            "tilted": _run(out / "tilted", true_tilt=TILTS)}


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_every_plus_minus_printed_is_a_quantity_s_expanded(runs, kind: str) -> None:
    result = runs[kind]
    assert result.statement, "the run states its machine"
    text = summary_text(result, verbose=True)
    # a value as stated, or its magnitude (advice says "leans … by 0.200 ± 0.021")
    stated = {t for q in result.statement for t in (plus_minus(q), plus_minus(q).lstrip("+-"))}
    printed = PM.findall(text)
    assert printed, "the summary prints values at 95 %"
    for line in text.splitlines():
        for match in re.finditer(r"([+−-]?\d+(?:\.\d+)? (?:mm )?± \d+(?:\.\d+)? "
                                 r"(?:µm|mm/m|mrad|µm/m))", line):
            said = match.group(1).replace("−", "-")
            assert said in stated, f"{said!r} in {line.strip()!r} is no stated quantity"


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_the_tool_s_intervals_are_the_statement_s(runs, kind: str) -> None:
    result = runs[kind]
    q = {x.name: x for x in result.statement or []}
    text = summary_text(result, verbose=False)
    for name in ("tool.after.rms", "tool.after.max", "tool.compensated.rms"):
        assert interval(q[name]) in text.replace("−", "-"), name
    after = q["tool.after.rms"]
    lo, hi = after.interval_95 or (0.0, 0.0)
    assert 0.0 <= lo <= (after.value or 0.0) <= hi
    # a max is never below its RMS, value and both ends
    mx = q["tool.after.max"]
    assert (mx.value or 0.0) >= (after.value or 0.0)
    assert mx.interval_95 is not None and mx.interval_95[0] >= lo and mx.interval_95[1] >= hi
    assert figure(after, "RMS") in text.replace("−", "-")


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_every_to_do_is_an_advice_text_and_none_contradict(runs, kind: str) -> None:
    result = runs[kind]
    texts = [a.text for a in result.advice or []]
    assert texts
    lines = summary_text(result, verbose=False).splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("  to do"))
    todo = [lines[start][16:]]
    for ln in lines[start + 1:]:  # an advice beyond 160 characters goes on at 18
        if ln.startswith(" " * 18):
            todo[-1] += " " + ln[18:]
        elif ln.startswith(" " * 16):
            todo.append(ln[16:])
    assert [t.replace("−", "-") for t in todo] == [t.replace("−", "-") for t in texts]
    ids = {a.id for a in result.advice or []}
    # no "nothing" beside an act; no rail advice beside "undecided"
    assert not ("nothing" in ids and len(ids) > 1)
    assert not ("undecided.layout" in ids and any(i.startswith(("shim.", "rail."))
                                                  for i in ids))
    gains = any(q.name == "tool.compensated.rms" and q.decision == "gain"
                for q in result.statement or [])
    for a in result.advice or []:
        if a.id.startswith(("shim.", "rail.")):
            assert ("controller" in a.text) == gains, a.text
        names = {q.name for q in result.statement or []}
        assert set(a.rests_on) <= names, a.id


def test_the_gaps_act_and_the_controller_gains_on_the_gapped_machine(runs) -> None:
    result = runs["gapped"]
    q = {x.name: x for x in result.statement or []}
    for name, true in zip(("gap_xy", "gap_xz", "gap_yz"), GAPS, strict=True):
        assert q[name].decision == "act"
        lo, hi = q[name].interval_95 or (0.0, 0.0)
        assert lo < true < hi, (name, lo, hi)
    assert q["tool.compensated.rms"].decision == "gain"
    ids = [a.id for a in result.advice or []]
    assert {"rail.gap_xy", "rail.gap_xz", "rail.gap_yz", "controller"} <= set(ids)


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_the_loop_s_verdict_is_the_statement_s(runs, kind: str) -> None:
    result = runs[kind]
    left = [q for q in result.statement or [] if q.name.endswith(".as_left")]
    assert len(left) == 3
    within = all(q.decision == "within" for q in left)
    assert result.converged is within
    assert (result.loop is not None and result.loop.stopped == "converged") is within
    for q in left:
        found = next(x for x in result.statement or [] if x.name ==
                     q.name.replace("as_left", "as_found"))
        assert found.expanded == q.expanded  # one uncertainty for the joint
    budget = result.uncertainty_budget
    assert budget is not None and not hasattr(budget, "error")
    for q in left:
        assert budget.expanded_95_mm[q.name.split(".")[0]] == pytest.approx(q.expanded)


# ------------------------------------------------------------------------ report.html

#: "± N" anywhere in a page's text: each is a stated quantity's, or one of the first
#: identification's stands (a nuisance of the fit, its own σ in mm, never a quantity of
#: the machine: the model test's words, under "The first identification").
ANY_PM = re.compile(r"(?:([+-]?\d+(?:\.\d+)?) (?:mm )?)?± (\d+(?:\.\d+)?) ?(µm/m|µm|mm/m|mrad|mm)?")
STAND = re.compile(r"stand_[xyz]{2} [+-]\d+\.\d+ ± \d+\.\d+ mm")
#: A tool figure's interval as every view prints it.
INTERVAL = re.compile(r"\(95 %: ([+-]?\d+\.\d)–([+-]?\d+\.\d) µm\)")


@pytest.fixture(scope="module")
def pages(runs) -> dict[str, str]:
    """Each run's report.html as the station writes it, its figures drawn."""
    return {kind: render_html(result, figures=True) for kind, result in runs.items()}


def page_text(page: str) -> str:
    """What the page says in words: no stylesheet, no figure, no tags; entities
    decoded; one minus sign (the page's U+2212 as ASCII, as quantity_text writes it)."""
    page = re.sub(r"<(svg|style|script)\b.*?</\1>", " ", page, flags=re.S)
    text = html.unescape(re.sub(r"<[^>]*>", " ", page))
    return re.sub(r"[ \t\n]+", " ", text).replace("\u2212", "-")


def _stated(result: RunResult) -> set[str]:
    """Every way the statement's quantities are printed: value ± U (signed, and its
    magnitude as the advice says it), its interval, a tool figure's."""
    out: set[str] = set()
    for q in result.statement or []:
        out |= {plus_minus(q), plus_minus(q).lstrip("+-"), interval(q)}
    return out


def linear(result: RunResult) -> list[str]:
    """The quantities stated with a ± (all but the tool's figures, stated as intervals)."""
    return [q.name for q in result.statement or [] if q.k is not None]


def assert_every_pm_is_stated(text: str, result: RunResult) -> int:
    """Each "± N" of ``text`` is a quantity of the statement (to the digits printed) or
    a stand of the first identification; returns how many were the statement's."""
    said = _stated(result)
    stands = {m.start() + m.group(0).index("±") for m in STAND.finditer(text)}
    count = 0
    for m in ANY_PM.finditer(text):
        at = m.start() + m.group(0).index("±")
        if at in stands:
            continue
        value, _, unit = m.groups()
        assert value is not None and unit is not None, text[max(0, at - 60):at + 40]
        printed = m.group(0)
        assert printed in said, (printed, text[max(0, at - 80):at + 40])
        count += 1
    return count


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_report_html_has_no_sigma_nor_std_err_figures_included(pages, kind: str) -> None:
    page = pages[kind]
    assert page.count("<svg") >= 3  # the figures are in it: their labels too
    # matplotlib writes every label as a comment beside its glyphs: the whole source
    for word in ("1σ", "3σ", "std err"):
        assert word not in page, word
    assert "95 % expanded uncertainty (the statement's U)" in page  # the figure's legend


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_every_plus_minus_of_report_html_is_a_quantity_s_expanded(runs, pages,
                                                                 kind: str) -> None:
    result, text = runs[kind], page_text(pages[kind])
    # Δρ as found and as left, tilts, gaps, squareness, reversals: each in the page's
    # statement table and again in its section, and every ± the page prints is one of them
    assert assert_every_pm_is_stated(text, result) >= 2 * len(linear(result))
    for q in result.statement or []:
        assert (plus_minus(q) if q.k is not None else interval(q)) in text, q.name
    # the tool's intervals, wherever printed, are the statement's
    tool = {interval(q).removesuffix(" µm") for q in result.statement or []
            if q.name.startswith("tool.")}
    found = INTERVAL.findall(text)
    assert found and all(f"{lo}–{hi}" in tool for lo, hi in found), found
    # and its tables' bare cells: the tool before → after, the geometry in the controller
    for name in ("tool.after.rms", "tool.after.max", "tool.compensated.rms"):
        q = next(x for x in result.statement or [] if x.name == name)
        assert f"{interval(q).removesuffix(' µm')}" in text, name


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_report_html_prints_every_advice_text_verbatim(runs, pages, kind: str) -> None:
    result, text = runs[kind], page_text(pages[kind])
    assert result.advice
    for a in result.advice:
        assert a.text.replace("\u2212", "-") in text, a.id
    # the legacy words of a second decision are gone: the rails' advice is the record's
    assert "not clearly less than the offsets'" not in text
    assert "beyond two standard errors" not in text


#: Writes what the reader sees (the laid-out text, figures aside) into the DOM, which
#: Chromium's --dump-dom prints.
SEEN = """<script>
window.addEventListener("load", () => {
  const out = document.createElement("pre"); out.id = "orthocal-seen";
  out.textContent = JSON.stringify({text: document.body.innerText,
    rows: document.querySelectorAll("#statement + table tbody tr").length,
    widest: document.documentElement.scrollWidth,
    page: document.documentElement.clientWidth});
  document.body.appendChild(out);
});
</script>"""


def test_a_reader_of_the_gapped_run_s_report_sees_the_statement(runs, pages,
                                                                tmp_path: Path) -> None:
    require(chromium() is not None, "Chromium (Debian's chromium package)")
    result = runs["gapped"]
    page = tmp_path / "report.html"
    page.write_text(pages["gapped"].replace("</body>", SEEN + "</body>"), encoding="utf-8")
    dom = browse(tmp_path, "--dump-dom", page.as_uri())
    m = re.search(r'<pre id="orthocal-seen">(.*?)</pre>', dom, re.S)
    assert m, "the page's script did not run"
    seen = json.loads(html.unescape(m.group(1)))
    # one row per quantity, nothing wider than the window
    assert seen["rows"] == len(result.statement or [])
    assert seen["widest"] <= seen["page"] + 1
    text = re.sub(r"\s+", " ", seen["text"]).replace("\u2212", "-")
    assert assert_every_pm_is_stated(text, result) >= 2 * len(linear(result))
    for word in ("1σ", "3σ", "std err"):
        assert word not in text


# ------------------------------------------------- the exports, the history, compare

INI = "[JOINT_0]\nHOME_OFFSET = 10.0\n[JOINT_1]\nHOME_OFFSET = 0\n[JOINT_2]\nHOME_OFFSET = 0\n"


def test_export_backlash_follows_the_statement_s_reversal_decision(runs) -> None:
    result = runs["gapped"]  # lost motion on joint z only (4 µm)
    q = {x.name: x for x in result.statement or []}
    assert q["reversal_z"].decision == "compensate"
    assert {q[f"reversal_{a}"].decision for a in "xy"} == {"none"}
    # the fakes' drive holds the offsets itself, which an export refuses to write twice:
    # here the station is taken to hold them, the backlash is what is read
    result = result.model_copy(update={"offsets_held_by": "station"})
    ini = linuxcnc(result, INI, backlash=True)
    written = re.findall(r"^BACKLASH = (\S+)\s+# (.*)$", ini, flags=re.M)
    assert [float(v) for v, _ in written] == pytest.approx([q["reversal_z"].value], abs=1e-6)
    assert f"reversal_z {plus_minus(q['reversal_z'])} (95 %)" in written[0][1]
    for a in "xy":  # not written, and why: the statement's words
        assert (f"# BACKLASH not written: the run's statement: reversal_{a} "
                f"{plus_minus(q[f'reversal_{a}'])} (95 %), not beyond its uncertainty "
                "(the decision table: none)") in ini
    rows = [r for r in twincat(result, backlash=True).splitlines()
            if "Backlash" in r and not r.startswith("#")]
    assert len(rows) == 1 and rows[0].split(",")[1] == "z"


@pytest.mark.parametrize("kind", ["gapped", "tilted"])
def test_the_hal_comments_and_model_json_are_the_statement_s(runs, kind: str) -> None:
    result = runs[kind]
    run_dir = Path(result.run_dir or "")
    q = {x.name: x for x in result.statement or []}
    model = json.loads((run_dir / "model.json").read_text(encoding="utf-8"))
    for a in "xyz":  # model.json's Δρ now is the statement's as left
        assert model["drho_now"][f"drho_{a}"] == pytest.approx(
            q[f"drho_{a}.as_left"].value, abs=1e-12)
    hal = geometry_hal(identified_machine(run_dir))
    said = dict(re.findall(r"^# (\w+) \(\w+\): .*; 95 %: \[(\S+, \S+)\]", hal, flags=re.M))
    for name in ("drho_x", "drho_y", "drho_z", "tilt_yx", "tilt_zx", "tilt_zy", "gap_xy",
                 "gap_xz", "gap_yz"):
        stated = q[f"{name}.as_left" if name.startswith("drho") else name]
        lo, hi = (float(v) for v in said[name].split(", "))
        assert (lo, hi) == pytest.approx(stated.interval_95, abs=1e-6), name
        assert f"{plus_minus(stated)} (95 %" in hal, name
    # every export's header: Δρ as left, as the statement states it
    header = " ".join(" ".join(line.removeprefix(HEADER).split())
                      for line in csv_lines(result).splitlines() if line.startswith(HEADER))
    for a in "xyz":
        assert f"{a} {plus_minus(q[f'drho_{a}.as_left'])}" in header


def test_the_history_and_compare_read_the_statements(runs) -> None:
    a, b = runs["tilted"], runs["gapped"]
    qa = {x.name: x for x in a.statement or []}
    qb = {x.name: x for x in b.statement or []}
    ea, eb = ({**entry_of(r), "machine_id": "OG-1"} for r in (a, b))
    points = series([{**ea, "started": "2026-01-01T10:00:00+00:00"}])
    for state in ("as found", "as left"):  # one uncertainty, the statement's
        p = next(p for p in points["drho_x"] if p.state == state)
        assert p.basis == "statement"
        assert p.expanded_95 == pytest.approx(qa[f"drho_x.{state.replace(' ', '_')}"].expanded)
    doc = compare(ea, eb)
    x = doc["joint_error_mm"]["x"]
    assert x["before_expanded"] == pytest.approx(qa["drho_x.as_left"].expanded)
    assert x["after_expanded"] == pytest.approx(qb["drho_x.as_found"].expanded)
    # the GUM's difference: the scatter and the mountings' inputs of each run, the legs'
    # straightness (the same legs) by the difference of its two parts
    ca, cb = qa["drho_x.as_left"].contributions or {}, qb["drho_x.as_found"].contributions or {}
    u2 = sum((cb.get(s, 0.0) - ca.get(s, 0.0)) ** 2 if s == "leg straightness" else
             ca.get(s, 0.0) ** 2 + cb.get(s, 0.0) ** 2 for s in set(ca) | set(cb))
    assert x["std_error"] == pytest.approx(u2 ** 0.5, rel=1e-9)
    assert x["interval_95"] == pytest.approx(x["k"] * x["std_error"], rel=1e-9)
    gap = doc["layout"]["gap_xy"]
    assert gap["before"] == pytest.approx(qa["gap_xy"].value)
    assert gap["after_expanded"] == pytest.approx(qb["gap_xy"].expanded)
    assert gap["significant"]  # 0.15 mm of gap from a square machine to a gapped one
    line = next(ln for ln in change_lines(doc) if ln.startswith("gap_xy"))
    assert plus_minus(qa["gap_xy"]) in line and plus_minus(qb["gap_xy"]) in line
