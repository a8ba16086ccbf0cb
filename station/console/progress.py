"""Run progress on stderr: the sequencer's events turned into station.console.terminal's live bar
(on a terminal) or plain lines (in a log)."""

from __future__ import annotations

from typing import Any

from station.plan.steps import Plan, posture_label


class Progress:
    """Run progress on stderr through station.console.terminal.RunProgress (a live bar on a
    terminal, plain lines in a log); one step per stop read."""

    def __init__(self, plan: Plan, verify: bool, enabled: bool = True) -> None:
        from station.console.terminal import RunProgress

        self.plan = plan
        per_phase = sum(1 + (len(sp.order) + 1) * plan.cycles for sp in plan.setups)
        self.bar = RunProgress(per_phase * (2 if verify else 1), enabled=enabled)
        self.steps = 0

    def __enter__(self) -> Progress:
        self.bar.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.bar.__exit__(None, None, None)

    def say(self, text: str) -> None:
        self.bar.message(text)

    def __call__(self, event: str, **info: Any) -> None:
        try:
            self._event(event, info)
        except Exception:
            pass  # a display glitch must never stop a run

    def _event(self, event: str, info: dict[str, Any]) -> None:
        code = info.get("phase", "")
        # "v2", "v3": the closed loop's later verifications; "v+1", "v2+1": one
        # measured again.
        base, _, again = code.partition("+")
        phase = {"m": "measure", "v": "verify"}.get(base) or (
            f"verify {base[1:]}" if base.startswith("v") else "")
        if again:
            phase += f", again ({again})"
        if event == "read":
            self.steps += 1
            sp = self.plan.setups[info["setup"]]
            posture = posture_label(info["sign"], sp.leg)
            self.bar.total_steps = max(self.bar.total_steps, self.steps)
            self.bar.update(f"{sp.index + 1}/{len(self.plan.setups)} (leg {sp.leg}, {phase})",
                            posture, max(info["cycle"], 1), self.plan.cycles, self.steps)
        elif event == "cycle":
            devs = " ".join(f"{k} {v:+.4f}" for k, v in info["deviations"].items())
            self.say(f"{phase} setup {info['setup'] + 1} cycle {info['cycle']}: {devs} mm")
        elif event == "cycle_replayed":
            # Replayed cycles count as done for the time estimate.
            sp = self.plan.setups[info["setup"]]
            self.steps += len(sp.order) + 1 + (1 if info["cycle"] == 1 else 0)
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
