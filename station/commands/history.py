"""``orthocal history`` and ``orthocal compare``: a machine's runs, and what changed
between two of them (docs/design.md, "Machine history")."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from station.commands.given_paths import file_to_write
from station.errors import BadInput

if TYPE_CHECKING:
    from station.record.result import RunResult


def _store(args: argparse.Namespace) -> Any:
    from station.history.store import HistoryStore, default_url

    runs = Path(args.out)
    url = args.db or default_url(runs)
    if args.db is None and args.rebuild is None and not (runs / "history.sqlite").exists():
        raise BadInput(f"--out: no history in {runs} (history.sqlite); runs record there "
                       "as they finish, or make it with --rebuild RUNS_DIR")
    if args.db is None and not runs.is_dir():  # the store's folder: the user's to make
        raise BadInput(f"--out: {runs} is not a directory")
    try:
        return HistoryStore(url)
    except Exception as exc:  # a bad URL or an unreachable server: one line
        which = "--db" if args.db is not None else "--out"  # the option that gave the URL
        raise BadInput(f"{which}: cannot open {url} ({type(exc).__name__}: {exc})") from None


def _plot(path: Path, entries: list[dict[str, Any]], machine: str | None) -> None:
    """``--plot``: one machine's runs drawn into ``path``; a history of several
    machines, or of none, is refused in one line (their parameters are not one
    machine's trend)."""
    from station.report.history_plot import plot_history

    machines = sorted({str(e.get("machine_id")) for e in entries if e.get("machine_id")})
    if machine is None and len(machines) > 1:
        raise BadInput(f"--plot: the history holds {len(machines)} machines "
                       f"({', '.join(machines)}); say which with --machine ID")
    mine = [e for e in entries if e.get("machine_id")] if machines else []
    if not mine:
        raise BadInput("--plot: no runs of a named machine ([machine] id) to plot"
                       + (f" for {machine!r}" if machine else ""))
    try:
        plot_history(mine, path, machines[0])
    except (KeyError, TypeError) as exc:  # a row written by another version, or edited
        raise BadInput(f"--plot: a history entry of {machines[0]} cannot be drawn "
                       f"({type(exc).__name__}: {exc}); --rebuild makes the store again "
                       "from the run directories") from None
    except ValueError as exc:
        raise BadInput(f"--plot: {exc}") from None
    except OSError as exc:
        raise BadInput(f"--plot: cannot write {path} ({exc.strerror})") from None
    print(f"orthocal: history of {machines[0]} drawn in {path}", file=sys.stderr)


def _plot_path(args: argparse.Namespace) -> Path | None:
    """The --plot file, its format checked before anything is read."""
    from station.report.history_plot import FORMATS

    if args.plot is None:
        return None
    path = Path(args.plot)
    if path.suffix.lower() not in FORMATS:
        raise BadInput(f"--plot: {args.plot}: suffix {path.suffix or '(none)'!r} is not "
                       "a figure format; give FILE.png or FILE.svg")
    file_to_write("--plot", path, replace=True)  # its folder too, before anything is read
    return path


#: Under the listing: what its two joint columns mean (docs/design.md "Machine
#: history"). A calibrated machine shows e ≈ −o, minus the offsets its controller
#: holds (e.g. −1818.6 µm), which alone would read as a machine 1.8 mm off.
LEGEND = ("Δρ as found: each joint's zero error at the run's start, with the offsets o "
          "the controller held then: what the run set out to correct (near 0 on a machine "
          "still in calibration). Δρ as left: the same at the run's end, with the offsets "
          "it left (after a rollback, as found again).\n"
          "e = Δρ − o: the same error without any offset, the machine's own (≈ −o on a "
          "machine in calibration): only e "
          "compares across runs whatever offsets were written in between, and its drift "
          "is the machine's.")


def _found_drho(entry: dict[str, Any], state: str = "as_found",
                offsets: str = "offsets_before") -> list[float | None]:
    """Δρ as found per axis: e + o with the offsets the run started from (``state``
    "as_left", ``offsets`` "offsets_final": Δρ as the run left the machine)."""
    found = (entry.get(state) or {}).get("joint_error_mm") or {}
    held = entry.get(offsets) or {}
    out: list[float | None] = []
    for a in "xyz":
        e, o = (found.get(a) or {}).get("value_mm"), held.get(a)
        out.append(None if e is None or o is None else e + o)
    return out


def drift_lines(entries: list[dict[str, Any]]) -> list[str]:
    """Per named machine, the drift of e per month ± 95 % (station.history.trend),
    or why none is stated."""
    from station.history.trend import drift, series, why_no_drift

    lines: list[str] = []
    for machine in sorted({str(e["machine_id"]) for e in entries if e.get("machine_id")}):
        points = series([e for e in entries if e.get("machine_id") == machine])
        found = {a: points.get(f"drho_{a}", []) for a in "xyz"}
        drifts = {a: drift(p) for a, p in found.items()}
        reasons = {why_no_drift(found[a]) for a, d in drifts.items() if d is None}
        if all(d is None for d in drifts.values()) and len(reasons) == 1:
            text = f"not stated, {reasons.pop()}"  # the usual case: said once
        else:
            text = "; ".join(f"{a} not stated, {why_no_drift(found[a])}" if d is None else
                             f"{a} {1000 * d.per_month:+.3g} ± {1000 * d.expanded_95:.2g} µm"
                             for a, d in drifts.items())
        lines.append(f"machine {machine}: drift of e per month ± 95 %: {text}")
    return lines


def history_main(args: argparse.Namespace) -> int:
    from station.history.compare import microns

    plot = _plot_path(args)
    if args.rebuild is not None and not Path(args.rebuild).is_dir():
        raise BadInput(f"--rebuild {args.rebuild}: no such folder of runs")
    with _store(args) as store:
        if args.rebuild is not None:
            count = store.rebuild(Path(args.rebuild))
            print(f"orthocal: history rebuilt from {count} run(s) in {args.rebuild}",
                  file=sys.stderr)
        entries = store.entries(args.machine)
    if plot is not None:
        _plot(plot, entries, args.machine)
    if args.json:
        print(json.dumps({"machine_id": args.machine, "runs": entries}, indent=2))
        return 0
    print(f"{'started':<26} {'machine':<12} {'state':<14} "
          f"{'as found Δρ (µm) x, y, z':<26} {'as left Δρ (µm) x, y, z':<26} "
          f"{'e = Δρ − o (µm) x, y, z':<26} tool after (µm RMS)   run")
    for e in entries:
        found = (e.get("as_found") or {}).get("joint_error_mm") or {}
        state = "rolled back" if e.get("rolled_back") else \
            e.get("stopped") or e.get("status") or "—"
        tool = e.get("tool_after_rms_mm")
        drho = ", ".join(microns(v) for v in _found_drho(e))
        # as left: e + the offsets the run left (after a rollback, back as found)
        left = ", ".join(microns(v) for v in _found_drho(e, "as_left", "offsets_final"))
        joint = ", ".join(microns((found.get(a) or {}).get("value_mm")) for a in "xyz")
        print(f"{e.get('started') or '—':<26} {e.get('machine_id') or '—':<12} {state:<14} "
              f"{drho:<26} {left:<26} {joint:<26} "
              f"{'—' if tool is None else f'{1000 * tool:.1f}':<19}   {e['run_dir']}")
        if (back := e.get("rolled_back")) and isinstance(back.get("restored"), dict):
            print(f"  rolled back {back.get('at') or ''}: offsets restored to " + ", ".join(
                f"{a} {back['restored'].get(a, float('nan')):+.4f}" for a in "xyz") + " mm")
    if not entries:
        print("(no runs" + (f" of machine {args.machine!r})" if args.machine else ")"))
        return 0
    print("\n".join(["", *drift_lines(entries), LEGEND]))
    return 0


def read_result(run_dir: str) -> tuple[Path, RunResult]:
    """RUN_DIR's result.json (of any version, as the current one: station.record.io.
    read_result) and its path; what cannot be read said in one line naming the file."""
    from station.record.io import UnreadableResult
    from station.record.io import read_result as read_record

    path = Path(run_dir) / "result.json"
    try:
        return path, read_record(path)
    except UnreadableResult as exc:
        raise BadInput(str(exc)) from None


def _entry_of_dir(run_dir: str) -> dict[str, Any]:
    from station.history.entry import entry_of, profile_of

    path, result = read_result(run_dir)
    if not result.finished:
        raise BadInput(f"{path}: the run has not finished")
    return entry_of(result, profile_of(Path(run_dir)))


def compare_main(args: argparse.Namespace) -> int:
    from station.history.compare import CRITERION, Incomparable, change_lines, compare

    if Path(args.run_a).resolve() == Path(args.run_b).resolve():
        # (a copy of one run directory is caught by compare: one run_dir in both)
        raise BadInput(f"compare: RUN_A and RUN_B are the same run ({args.run_a}): give "
                       "two runs of one machine")
    a, b = _entry_of_dir(args.run_a), _entry_of_dir(args.run_b)
    try:
        doc = compare(a, b)
    except Incomparable as exc:
        raise BadInput(f"compare: {exc}") from None
    if args.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"machine {doc['machine_id']}: A {doc['a']} ({doc['a_state']}) → B {doc['b']} "
          "(as found)")
    for line in change_lines(doc):
        print(f"  {line}")
    print(f"  {CRITERION}")
    return 0
