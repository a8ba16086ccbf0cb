"""Run progress on stderr: the sequencer's events turned into station.console.terminal's live bar
(on a terminal) or plain lines (in a log)."""

from __future__ import annotations

from typing import Any

from station.plan.steps import Plan, Read, posture_label
from station.record.phase import Phase


class Progress:
    """Run progress on stderr through station.console.terminal.RunProgress (a live bar on a
    terminal, plain lines in a log); one step per stop read.

    The total counts the plan's reads (the one-side approach's extra stop included)
    for the usual run, a measurement and one verification (each pass's own setups: a
    second gauge plane is read in the run's second pass alone); a further phase (another
    write-back, a pass measured again) or a cycle more in a mounting adds its reads
    as it starts, saying so ("+4 readings: another cycle …", the bar re-based), so
    the bar never reads more done than it counts and its time left rises only there."""

    def __init__(self, plan: Plan, verify: bool, enabled: bool = True) -> None:
        from station.console.terminal import RunProgress

        self.plan = plan
        # a pass's reads: the run's pass n measures the plan's setups_of(n), a second
        # gauge plane in one pass alone (station.plan.steps.Plan.setups_of)
        self.per_pass = [self._reads(n) for n in (0, 1, 2)]
        reads = [s for s in plan.steps("m") if isinstance(s, Read)]
        self.per_cycle = {sp.index: sum(1 for r in reads if r.setup == sp.index
                                        and r.cycle == 1) for sp in plan.setups}
        self.expected_phases = 2 if verify else 1
        self.bar = RunProgress(sum(self.per_pass[:self.expected_phases]), enabled=enabled)
        self.steps = 0
        self._phases: set[str] = set()
        self._more: set[tuple[str, int, int]] = set()
        # the cycles each mounting (phase, setup) has taken so far, at least the plan's
        self._cycles: dict[tuple[str, int], int] = {}

    def _count(self, code: str, phase: str, setup: int, cycle: int) -> None:
        """Grow the total by what the run turned out to take beyond the usual, and
        say so."""
        if code not in self._phases:
            self._phases.add(code)
            if len(self._phases) > self.expected_phases:
                n = min(len(self._phases), len(self.per_pass)) - 1
                self.bar.rebase(self.per_pass[n], f"another pass ({phase})")
        key = (code, setup)
        self._cycles[key] = max(self._cycles.get(key, self.plan.cycles), cycle)
        if cycle > self.plan.cycles and (code, setup, cycle) not in self._more:
            self._more.add((code, setup, cycle))
            self.bar.rebase(self.per_cycle.get(setup, 0),
                            f"another cycle ({phase} setup {setup + 1}, cycle {cycle})")

    def _reads(self, index: int) -> int:
        """The reads of the run's pass ``index`` at the planned cycles."""
        return sum(1 for s in self.plan.steps("m", index) if isinstance(s, Read))

    def __enter__(self) -> Progress:
        self.bar.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.bar.__exit__(None, None, None)

    def say(self, text: str) -> None:
        self.bar.message(text)

    def finished(self) -> None:
        """The run's readings are all taken (its closed loop has finished): the one
        place the bar says "done"."""
        try:
            self.bar.finish()
        except Exception:
            pass  # a display glitch must never stop a run

    def __call__(self, event: str, **info: Any) -> None:
        try:
            self._event(event, info)
        except Exception:
            pass  # a display glitch must never stop a run

    def _event(self, event: str, info: dict[str, Any]) -> None:
        code = info.get("phase", "")
        # "v2", "v3": the closed loop's later verifications; "v+1", "v2+1", "m+1": one
        # measured again (station.record.phase)
        try:
            phase = Phase.parse(code).label
        except ValueError:
            phase = ""
        if event == "read":
            self.steps += 1
            sp = self.plan.setups[info["setup"]]
            self._count(code, phase, sp.index, int(info["cycle"]))
            posture = posture_label(info["sign"], sp.leg)
            self.bar.update(f"{sp.index + 1}/{len(self.plan.setups)} (leg {sp.leg}, {phase})",
                            posture, max(info["cycle"], 1),
                            self._cycles.get((code, sp.index), self.plan.cycles), self.steps)
        elif event == "cycle":
            devs = " ".join(f"{k} {v:+.4f}" for k, v in info["deviations"].items())
            self.say(f"{phase} setup {info['setup'] + 1} cycle {info['cycle']}: {devs} mm")
        elif event == "cycle_replayed":
            # Replayed cycles count as done for the time estimate.
            sp = self.plan.setups[info["setup"]]
            self._count(code, phase, sp.index, int(info["cycle"]))
            self.steps += self.per_cycle[sp.index] + (1 if info["cycle"] == 1 else 0)
            self.say(f"{phase} setup {info['setup'] + 1} cycle {info['cycle']}: "
                     "from the journal")
        elif event == "repeat":
            self.say(f"{phase} setup {info['setup'] + 1}: spread {info['spread']:.4f} mm "
                     "above repeatability_mm, repeating its cycles")
        elif event == "setup_done":
            o = info["outcome"]
            flag = " (FLAGGED: above repeatability_mm)" if o.flagged else ""
            self.say(f"{phase} setup {o.index + 1} done: {o.cycles_used} cycle(s), "
                     f"spread {o.spread_mm:.4f} mm{flag}")
        elif event == "joint_tested":
            rec = info["record"]
            how = "from the journal" if info.get("replayed") else \
                f"{len(rec.targets_mm)} targets, drift {rec.test.drift_um:+.1f} µm"
            self.say(f"joint {rec.joint}'s own test against the {rec.test.reference}: "
                     f"{how}")
