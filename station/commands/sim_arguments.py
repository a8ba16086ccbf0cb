"""The virtual machine's options, shared by ``orthocal run --simulate`` and ``orthocal
sim`` (docs/design.md, "Command line"): its hidden errors, its gauges' noise and
stands, its screws and its drive. Light, as the command line is: parsed before numpy
is loaded; their values are checked in station.commands.simulate.launch (one line
naming the option, exit 2)."""

from __future__ import annotations

import argparse

from station.commands.arg_types import not_negative, triple, whole


def add_sim_options(p: argparse.ArgumentParser) -> None:
    """Add the virtual machine's options to ``p``."""
    p.add_argument("--seed", type=whole(0), default=None, help="seed of the virtual machine")
    p.add_argument(
        "--true-drho",
        type=triple,
        metavar="X,Y,Z",
        help="hidden joint offsets of the virtual machine (mm; random if absent)",
    )
    p.add_argument(
        "--true-dl",
        type=triple,
        metavar="X,Y,Z",
        help="hidden leg-length errors of the virtual machine (mm; zero if absent)",
    )
    p.add_argument(
        "--true-tilt",
        type=triple,
        metavar="X,Y,Z",
        help="hidden actuator axis tilts tilt_yx, tilt_zx, tilt_zy of the virtual machine "
        "(mrad; zero if absent)",
    )
    # A string, checked in station.commands.simulate.launch.gaps_mm: a bad value is one
    # line naming the option, exit 2 (argparse's own error would print the usage too).
    p.add_argument(
        "--true-gap",
        type=str,
        default=None,
        metavar="X,Y,Z",
        help="hidden gaps gap_xy, gap_xz, gap_yz of the virtual machine's actuator axes "
        "(mm, either sign; zero if absent): how far axis x passes axis y along +z, x "
        "passes z along +y, y passes z along +x",
    )
    p.add_argument(
        "--noise", type=not_negative, default=None, metavar="MM",
        help="indicator noise sigma in mm"
    )
    p.add_argument(
        "--profile", metavar="MAP", default=None,
        help="the register map the virtual drive serves, a built-in name or a .toml file "
             "(docs/design.md, Register-map files): its addresses, types, word order, scale, "
             "tables, devices and command sequences, as a drive of that layout would; the "
             "config it hands the station names it (default orthocal-generic)",
    )
    p.add_argument(
        "--backlash", type=str, default=None, metavar="X,Y,Z",
        help="lost motion of each joint (mm, ISO 230-2's reversal value: the carriage "
             "follows the counted position through a dead band this wide; one value for "
             "all or x,y,z; default 0)",
    )
    p.add_argument(
        "--leg-bow", type=str, default=None, metavar="X,Y,Z",
        help="form error of each leg (mm): the sagitta of its surface at its middle, "
             "seen by a gauge's plunger where it touches the leg (4h·t(1-t) at the "
             "fraction t along it); one value for all legs or x,y,z; default 0",
    )
    p.add_argument(
        "--joint-lead", type=str, default=None, metavar="X,Y,Z",
        help="lead error of each joint's screw, µm per metre of travel from home (the "
             "virtual drive homes at Π0): the carriage travels (1 + k·1e-6) times what "
             "the drive counts; one value for all or x,y,z; default 0",
    )
    p.add_argument(
        "--joint-pitch", type=str, default=None, metavar="AMPLITUDE_UM,PERIOD_MM",
        help="periodic (pitch) error of every joint's screw: A·sin(2π·travel/P) from "
             "home, amplitude in µm and period in mm; default none",
    )
    p.add_argument(
        "--joint-test", action="store_true", default=None,
        help="the station tests each joint's positioning itself before the calibration, "
             "against the virtual station's gauge blocks read with its gauge A on the "
             "carriage ([joints] station_test; docs/model.md, \"The station's own joint "
             "test\"): what --joint-lead and --joint-pitch do, it finds",
    )
    p.add_argument(
        "--gauge-scale", type=str, default=None, metavar="S[,S...]",
        help="scale error of the gauges, relative (0.002: each reads 0.2%% too much of "
             "its plunger's travel); one value for all or one per gauge in the order "
             "of the config's indicators; default 0",
    )
    p.add_argument(
        "--mount-error", type=not_negative, default=None, metavar="MM",
        help="indicator stands placed by eye: each mounting is off the leg's middle by a "
             "hidden random amount uniform in +-MM (default 5; 0: perfectly placed)",
    )
    p.add_argument("--gauges", choices=["pty", "tcp"], default=None, help=(
        "where the virtual gauges' serial lines end: pseudo-terminals (pty, the default "
        "where the system has them: Linux, macOS) or sockets on 127.0.0.1 that the station "
        "opens as socket:// URLs (tcp, the default elsewhere: Windows)"))
    p.add_argument(
        "--motion", choices=["coordinated", "independent"], default=None,
        help="how the virtual controller moves its axes: together on the straight line "
             "(coordinated, the default; the config then says so) or each on its own "
             "profile (independent, the default with --drive-delays or --drive-sequence "
             "and with a map whose axes are separate drives, unit ids, where coordinated is "
             "refused; the config then says nothing, as for a drive that does not "
             "interpolate)",
    )
    # The virtual drive's own behaviour, never written to the config it hands the
    # station: what a real drive does without saying (docs/design.md, "Register map").
    # Strings here, checked in station.commands.simulate.launch: a bad value is one line, exit 2.
    p.add_argument(
        "--drive-profile", metavar="SHAPE[,SHAPE,SHAPE]", default=None,
        help="the virtual drive's profile shape: trapezoid (default), scurve "
             "(jerk-limited) or cosine; one for all axes or x,y,z (independent only)",
    )
    p.add_argument(
        "--drive-accel", metavar="MM_S2[,MM_S2,MM_S2]", default=None,
        help="the virtual drive's own acceleration (mm/s²; one, or x,y,z when "
             "independent), while the config still tells the station the default one",
    )
    p.add_argument(
        "--drive-delays", metavar="X,Y,Z", default=None,
        help="start delay of each axis after the move command (s, >= 0; independent)",
    )
    p.add_argument(
        "--drive-sequence", metavar="ORDER", default=None,
        help="the virtual drive moves one axis after another in this order, e.g. zyx "
             "(the next starts when the previous has arrived; independent)",
    )
