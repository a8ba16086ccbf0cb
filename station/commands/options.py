"""What ``run``, ``resume`` and ``rollback`` are asked to do, typed.

The command line builds these from its arguments (``from_args``); tests and
benches build them directly. Nothing below the commands sees argparse.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from station.record.simulated import Triple

# A callable given the running virtual station (tests inject its faults through it).
StationHook = Callable[[Any], None]


@dataclass(frozen=True)
class DriveOptions:
    """How the virtual controller moves its axes (``--motion``, ``--drive-*``), as
    given: text, checked by station.commands.simulate.launch.drive_params."""

    motion: str | None = None
    profile: str | None = None
    accel: str | None = None
    delays: str | None = None
    sequence: str | None = None

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> DriveOptions:
        return cls(motion=args.motion, profile=args.drive_profile, accel=args.drive_accel,
                   delays=args.drive_delays, sequence=args.drive_sequence)


@dataclass(frozen=True)
class SimOptions:
    """The virtual station of ``run --simulate``: its hidden errors (None: random
    offsets, no leg-length error, no tilt, axes that meet, straight legs, true
    gauges, exact screws), noise, stands and drive; and what the command line does not offer: the
    six-indicator style, procedure, write-back and report overrides, a faster machine, and a
    hook that reaches the running station."""

    seed: int | None = None
    true_drho: Triple | None = None
    true_dl: Triple | None = None
    true_tilt: Triple | None = None
    # "X,Y,Z" as given on the command line, or three values: gap_xy, gap_xz, gap_yz, mm
    true_gap: str | Triple | None = None
    noise: float | None = None
    mount_error: float | None = None
    backlash: str | None = None  # "X,Y,Z" or one value, mm
    leg_bow: str | None = None  # "X,Y,Z" or one value, mm: each leg's sagitta
    gauge_scale: str | None = None  # one relative error for all gauges, or one each
    joint_lead: str | None = None  # "X,Y,Z" or one value, µm per metre of travel from home
    joint_pitch: str | None = None  # "AMPLITUDE_UM,PERIOD_MM": one periodic error for all
    # the station's own test of the joints against the virtual gauge blocks (--joint-test)
    joint_test: bool | None = None
    profile: str | None = None  # the register map the virtual drive serves
    gauges: str | None = None  # "pty" or "tcp": where the gauges' lines end (None: the system's)
    drive: DriveOptions = field(default_factory=DriveOptions)
    indicators: int = 2
    procedure: Mapping[str, Any] | None = None
    writeback: Mapping[str, Any] | None = None
    report: Mapping[str, Any] | None = None  # the config's [report] for the run
    # what the run states of its inputs ([uncertainty]) over the virtual station's own
    uncertainty: Mapping[str, Any] | None = None
    speed_mm_s: float | None = None
    station_hook: StationHook | None = None

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> SimOptions:
        # --sim-procedure and --sim-speed: hidden, for tests that drive the real
        # command line in a subprocess (Ctrl-C, kill -9) and need a short run
        return cls(seed=args.seed, true_drho=args.true_drho, true_dl=args.true_dl,
                   true_tilt=args.true_tilt, true_gap=args.true_gap,
                   noise=args.noise, mount_error=args.mount_error,
                   backlash=args.backlash, leg_bow=args.leg_bow,
                   gauge_scale=args.gauge_scale, profile=args.profile,
                   gauges=args.gauges, joint_lead=args.joint_lead,
                   joint_pitch=args.joint_pitch, joint_test=args.joint_test,
                   drive=DriveOptions.from_args(args),
                   procedure=getattr(args, "sim_procedure", None),
                   speed_mm_s=getattr(args, "sim_speed", None))


@dataclass(frozen=True)
class RunOptions:
    """``orthocal run``: against the devices of ``config``, or the virtual station
    of ``sim``; ``plan``: print the checked plan and exit."""

    config: Path | None = None
    sim: SimOptions | None = None
    plan: bool = False
    offsets_from: Path | None = None  # --offsets-from RUN_DIR
    out: Path = Path("runs")
    yes: bool = False
    json: bool = False
    verbose: bool = False  # the whole summary, not its first screen only
    operator: str | None = None  # --operator NAME: over the config's [station] operator

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> RunOptions:
        return cls(config=None if args.config is None else Path(args.config),
                   sim=SimOptions.from_args(args) if args.simulate else None,
                   plan=bool(args.plan), out=Path(args.out), yes=bool(args.yes),
                   json=bool(args.json), verbose=bool(getattr(args, "verbose", False)),
                   operator=getattr(args, "operator", None),
                   offsets_from=None if getattr(args, "offsets_from", None) is None
                   else Path(args.offsets_from))


@dataclass(frozen=True)
class ResumeOptions:
    """``orthocal resume`` and ``orthocal rollback`` of the run in ``run_dir``;
    ``station_hook``: given the restarted virtual station of a simulated run."""

    run_dir: Path
    yes: bool = False
    json: bool = False
    station_hook: StationHook | None = None
    verbose: bool = False  # the whole summary, not its first screen only

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> ResumeOptions:
        return cls(run_dir=Path(args.run_dir), yes=bool(args.yes), json=bool(args.json),
                   verbose=bool(getattr(args, "verbose", False)))

