"""Every mount prompt of a run names its picture, drawn into the run directory before
the first prompt, and report.html shows them (docs/design.md, "Mounting pictures");
a resumed run keeps the pictures its operator was shown and draws those missing."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from builders import FAST
from fakes import FakeRig, fake_config, run_on

from orthocal.postures import MIDDLE
from station.console.operator import VirtualOperator, mount_instruction
from station.engine.procedure import draw_mountings
from station.plan.steps import build_plan

PICTURE = re.compile(r"^  picture: (.+)$", re.M)


class Prompted(FakeRig):
    """The rig, its operator keeping every mount prompt as the console would show it."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.prompts: list[tuple[int, str, str]] = []  # (setup, leg, the prompt)

    def operator(self) -> VirtualOperator:
        rig = self

        class Keeping(VirtualOperator):
            def mount(self, phase: str, setup: int, leg: str, indicators: Mapping[str, str],
                      all_names: Sequence[str], at: float = MIDDLE, **words: Any) -> None:
                rig.prompts.append((setup, leg, mount_instruction(
                    phase, setup, leg, indicators, all_names, at, **words)))
                super().mount(phase, setup, leg, indicators, all_names, at, **words)

        return Keeping(self.mount, self.unmount)


def test_every_prompt_of_a_run_names_its_picture_and_the_report_shows_them(
        tmp_path: Path) -> None:
    rig = Prompted(true_drho=(0.4, -0.3, 0.2))
    code, result = run_on(rig, tmp_path, fake_config(**FAST))
    assert code == 0, result.get("message")
    run_dir = Path(result["run_dir"])
    assert len(rig.prompts) >= 4  # three setups measured, and a verification's mounting
    for setup, leg, prompt in rig.prompts:
        named = PICTURE.findall(prompt)
        assert named == [str(run_dir / f"mounting-{setup + 1}-leg-{leg}.svg")], prompt
        picture = Path(named[0])
        assert picture.is_file() and picture.read_text().startswith("<svg")
        assert f'data-leg="{leg}"' in picture.read_text()
        assert "push in " in prompt and "stand: 155.1 mm (L/2)" in prompt
    pictures = sorted(p.name for p in run_dir.glob("mounting-*.svg"))
    assert pictures == ["mounting-1-leg-x.svg", "mounting-2-leg-y.svg", "mounting-3-leg-z.svg"]
    page = (run_dir / "report.html").read_text(encoding="utf-8")
    assert "<h2>Mountings</h2>" in page
    assert page.count('<figure class="mounting">') == 3
    for name in pictures:  # inline, as drawn (without figures too: [report] figures off)
        svg = (run_dir / name).read_text(encoding="utf-8").strip()
        assert f"<figcaption>{name}</figcaption>" in page and svg in page


def test_a_resumed_run_keeps_the_pictures_it_has_and_draws_those_missing(
        tmp_path: Path) -> None:
    config = fake_config()
    plan = build_plan(config)
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    kept = run_dir / "mounting-2-leg-y.svg"
    kept.write_text("<svg>as the operator saw it</svg>")

    class Ctx:  # what draw_mountings reads of a run
        pass

    ctx: Any = Ctx()
    ctx.run_dir, ctx.config, ctx.plan = run_dir, config, plan
    draw_mountings(ctx)
    assert kept.read_text() == "<svg>as the operator saw it</svg>"
    for name in ("mounting-1-leg-x.svg", "mounting-3-leg-z.svg"):
        assert (run_dir / name).read_text().startswith("<svg xmlns")
