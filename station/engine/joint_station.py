"""The station's own test of the joints (docs/design.md, "Joints"; docs/model.md, "The
station's own joint test"), run before the calibration's first measurement so that
the identification and the tool's statement of the same run rest on its tables.

Each joint's test is one step of the journal's one executor
(station.engine.replay.Steps, :class:`~station.engine.replay.JointTestStep`): its
record, ``joint-test``, holds the table it found, and a resumed run replays a joint
whose record is there. A test cut off before its record is taken again from its
mounting: its readings belong to a gauge and a reference that may have moved. Its
steps are the checked plan's (station.plan.joint_test_plan): moves through the
sequencer's mover (re-routed from where the axes stand, no leg gauge on), the
operator's part through the operator (the mounting, each face, the gauge and the
reference off: each journaled with the operator's time), every reading journaled
and fsynced before the next move, outliers rejected as at a stop of a cycle.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from station.analysis import joints
from station.analysis.joint_readings import Approaches, details_of, tables_of, tested_record
from station.analysis.statistics import NoiseScale, reject_outliers
from station.engine.flow import Run
from station.engine.replay import JointTestStep
from station.engine.run_record import RunRecord
from station.engine.sequencer import Sequencer
from station.errors import RunFailed, StorageFull, check_interrupted, storage_message
from station.plan.joint_test_plan import (
    FaceSet,
    JointMount,
    JointRead,
    JointTestPlan,
    JointUnmount,
    StationTest,
)
from station.plan.steps import Move, Settle
from station.record.journal import JointTested
from station.report.joint_picture import file_name, write_joint_pictures


def station_test(ctx: Run) -> StationTest | None:
    """The plan's own test of the joints (None: none asked for)."""
    test = ctx.plan.station_test
    assert test is None or isinstance(test, StationTest)
    return test


def draw_pictures(ctx: Run) -> None:
    """Each tested joint's set-up picture into the run directory, before its first
    prompt names it (a resumed run draws only those missing)."""
    test = station_test(ctx)
    if test is None:
        return
    try:
        write_joint_pictures(ctx.run_dir, test, ctx.config, missing_only=True)
    except OSError as exc:
        raise StorageFull(storage_message(ctx.run_dir, exc)) from None


def test_joints(ctx: Run, seq: Sequencer, record: RunRecord,
                progress: Callable[..., None]) -> dict[str, JointTested]:
    """Every joint's own test the plan holds, each taken or replayed from its record;
    the records by axis, and result.json's ``joints`` stating their tables. A fault
    stops the axes (the sequencer's abort) and propagates."""
    test = station_test(ctx)
    if test is None:
        return {}
    draw_pictures(ctx)
    tester = JointTester(ctx, seq, progress)
    try:
        for jp in test.joints:
            def act(jp: JointTestPlan = jp) -> None:
                tester.run(jp)

            done = ctx.steps.take(JointTestStep(jp.axis), act, replayed=lambda rec: progress(
                "joint_tested", joint=rec.joint, record=rec, replayed=True))
            assert done is not None, "a joint's test journals its record"
    except BaseException as exc:
        seq.abort(exc)
        raise
    found = {jp.axis: ctx.state.joint_tests[jp.axis] for jp in test.joints}
    record.joints(joints.fields(joints.of_run_config(ctx.config, tables_of(found)),
                                details_of(found)))
    return found


class JointTester:
    """Takes one joint's test through its steps (module docstring)."""

    def __init__(self, ctx: Run, seq: Sequencer, progress: Callable[..., None]) -> None:
        self.ctx, self.seq, self.progress = ctx, seq, progress
        self.names = [ind.name for ind in ctx.config.indicators]
        self.noise = NoiseScale()

    def run(self, jp: JointTestPlan) -> None:
        """The joint's steps, then its record (``joint-test``), fsynced."""
        mover = self.seq.mover
        mover.setup, mover.mounted = None, {}  # no leg gauge: moves routed without one
        self.noise = NoiseScale()  # the test gauge's scatter, pooled over its approaches
        got = Approaches()
        for step in jp.steps():
            check_interrupted()
            if isinstance(step, Move):
                mover.move(step)
                self.seq.counters.moves = mover.moves
            elif isinstance(step, Settle):
                if step.seconds > 0:
                    time.sleep(step.seconds)
            elif isinstance(step, JointRead):
                self._read(step, jp, got)
            else:
                self._ask(step, jp)
        try:
            record = tested_record(self.ctx.config, jp, got)
        except ValueError as exc:
            raise RunFailed(f"joint {jp.axis}'s own test: {exc}") from None
        self.ctx.journal.append(record)
        self.progress("joint_tested", joint=jp.axis, record=self.ctx.state.joint_tests[jp.axis],
                      replayed=False)

    def _ask(self, step: JointMount | FaceSet | JointUnmount, jp: JointTestPlan) -> None:
        """The operator's part, journaled with the time it took."""
        picture = str(self.ctx.run_dir / file_name(jp.axis)) \
            if isinstance(step, JointMount) else None
        self.progress("prompt", phase="j", setup=jp.index)
        asked = time.monotonic()
        self.ctx.operator.joint_test(step, jp, self.names, picture=picture)
        operator_s = round(time.monotonic() - asked, 3)
        position = self.seq.mover.position
        if isinstance(step, JointMount):
            self.seq.mover.mount({})  # a new mounting: full speed, no recoveries yet
            self.ctx.journal.append({
                "type": "joint-mount", "joint": jp.axis, "gauge": step.gauge,
                "operator_s": operator_s,
                "position": None if position is None else [float(v) for v in position]})
        elif isinstance(step, FaceSet):
            self.ctx.journal.append({"type": "joint-face", "joint": jp.axis,
                                     "target": step.target, "face_mm": step.face_mm,
                                     "operator_s": operator_s})
        else:
            self.ctx.journal.append({"type": "joint-unmount", "joint": jp.axis,
                                     "gauge": step.gauge, "operator_s": operator_s})

    def _read(self, step: JointRead, jp: JointTestPlan, got: Approaches) -> None:
        """``step.n`` readings, each journaled (fsynced) before anything moves on; the
        approach's mean of those that are not outliers."""
        proc = self.ctx.config.procedure
        values = [float(v) for v in self.seq.indicators.read(step.n, [step.gauge])[step.gauge]]
        self.ctx.journal.append({"type": "reading", "stop": step.stop,
                                 "indicator": step.gauge, "values": values})
        ind = self.ctx.config.indicator(step.gauge)
        self.noise.add(values)
        keep = reject_outliers(values, proc.outlier_k, 3.0 * ind.resolution_mm, self.noise.sigma)
        rejected = [v for v, k in zip(values, keep, strict=True) if not k]
        if rejected:
            self.ctx.journal.append({"type": "outlier", "stop": step.stop,
                                     "indicator": step.gauge, "rejected": rejected,
                                     "median": float(np.median(values))})
            self.seq.counters.rejected += len(rejected)
        self.seq.counters.readings += len(values)
        kept = [v for v, k in zip(values, keep, strict=True) if k]
        here = self.seq.mover.position
        got.add(step.target, step.side, float(np.mean(kept)),
                None if here is None else float(here[jp.index]))
        self.progress("joint_read", joint=jp.axis, stop=step.stop, values=values)
