"""The virtual station (drivers.sim) as the station uses it: the calibration's
setups for its gauges and its description in station.toml's shape.

drivers.sim knows hardware only — a machine, a drive, gauges that wait to be
mounted. Which gauges a calibration moves where is the station's: two styles,
``TWO_SETUPS`` (A and B moved from leg to leg; the operator re-mounts them before
each setup) and ``SIX_SETUPS`` (A..F, two per leg; D mounted reversed to exercise
the sign convention). :func:`gauges_for` names a station's gauges after one of
them, and :class:`SimulatedStation` describes itself as the config a simulated run
uses (:meth:`SimulatedStation.config`): what an integrator would write of it.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from drivers.sim.specs import GaugeSpec, Mounting
from drivers.sim.station import VirtualStation

TWO_SETUPS: list[dict[str, Any]] = [
    {"leg": "x", "indicators": {"A": "y", "B": "z"}},
    {"leg": "y", "indicators": {"A": "x", "B": "z"}},
    {"leg": "z", "indicators": {"A": "x", "B": "y"}},
]
SIX_SETUPS: list[dict[str, Any]] = [
    {"leg": "x", "indicators": {"A": "y", "B": "z"}},
    {"leg": "y", "indicators": {"C": "x", "D": "-z"}},
    {"leg": "z", "indicators": {"E": "x", "F": "y"}},
]
# The controller's reply timeout the description gives: a virtual drive on the
# loopback answers in milliseconds, and a lost reply is found out in a second.
CONTROLLER_TIMEOUT_S = 1.0
#: A station in another process (``orthocal sim --joint-test``): a gauge on each
#: carriage from the start and a step gauge standing beside each rail, 20 mm faces
#: calibrated to 0.5 µm at 20 °C, its face set as the station asks
#: (drivers.sim.length_reference.VirtualReference.standing), the datum where the station puts
#: it for this machine: on the lower soft limit (station.plan.joint_test_plan).
JOINT_GAUGES = {"x": "G", "y": "H", "z": "I"}
STEP_GAUGE: dict[str, Any] = {"kind": "step gauge", "faces_mm": [20.0 * k for k in range(11)],
                              "u_mm": 0.0005, "temperature_c": 20.0, "plunger": "-"}
#: How well a shop measures a leg's straightness (mm): the stated bound is the bow the
#: simulation gives the leg plus this.
STRAIGHTNESS_READ_MM = 0.0005
#: The temperature change during a run a shop with a held room states (°C).
ROOM_HELD_C = 0.1


def joint_bound_um_per_m(lead_um_per_m, pitch_um: float = 0.0,
                         pitch_period_mm: float = 0.0) -> float:
    """The bound per metre of travel from home a shop that measured these screws states
    ([uncertainty] joint_positioning_um_per_m): the largest |lead|, plus 2π·A/P of a
    periodic error (|A·sin(2π·x/P)| ≤ 2π·A·|x|/P); 0 for exact screws (stated exact)."""
    pitch = 2e3 * math.pi * pitch_um / pitch_period_mm if pitch_um and pitch_period_mm \
        else 0.0
    return round(max(abs(float(k)) for k in lead_um_per_m) + pitch, 3)


def setups_of(count: int) -> list[dict[str, Any]]:
    """The setups of the ``count``-gauge style: 2 (moved leg to leg) or 6 (two per leg)."""
    if count not in (2, 6):
        raise ValueError("indicator count must be 2 (moved leg to leg) or 6 (two per leg)")
    return TWO_SETUPS if count == 2 else SIX_SETUPS


def _names(setups: list[dict[str, Any]]) -> tuple[str, ...]:
    return tuple(sorted({n for s in setups for n in s["indicators"]}))


def gauges_for(count: int, spec: GaugeSpec | None = None, *,
               mounted: bool = False) -> GaugeSpec:
    """``spec`` (None: the defaults) with the gauges of the ``count``-gauge setups,
    in name order; ``mounted``: each already where its setup puts it (a station in
    another process cannot be told where the operator mounted them)."""
    setups = setups_of(count)
    mountings: tuple[Mounting, ...] = tuple(
        (name, s["leg"], direction) for s in setups
        for name, direction in s["indicators"].items()) if mounted else ()
    return dataclasses.replace(spec or GaugeSpec(), names=_names(setups), mounted=mountings)


class SimulatedStation(VirtualStation):
    """A virtual station whose gauges are those of a calibration's setups
    (:func:`gauges_for`), which describes itself to the station (:meth:`config`).
    A test may replace ``config`` on an instance: its description stands for what a
    user writes in the file."""

    def stand_joint_gauges(self) -> None:
        """:data:`JOINT_GAUGES` on their carriages against :data:`STEP_GAUGE` beside
        each rail, the datum on the drive's lower soft limit: what a station in another
        process tests its joints with."""
        for axis, name in JOINT_GAUGES.items():
            i = "xyz".index(axis)
            self.stand_joint_gauge(name, axis, -1, STEP_GAUGE["faces_mm"],
                                   float(self.controller.soft_min[i]))
        self._joint_gauges = dict(JOINT_GAUGES)

    @property
    def joint_gauges(self) -> dict[str, str]:
        """The gauges standing on the carriages for the joints' own test, by joint
        (none until :meth:`stand_joint_gauges`)."""
        return dict(getattr(self, "_joint_gauges", {}))

    @property
    def setups(self) -> list[dict[str, Any]]:
        """The setups of its gauges (A and B: moved leg to leg; A..F: two per leg; the
        joints' own test's gauges aside)."""
        names = tuple(n for n in self.gauge_spec.names if n not in JOINT_GAUGES.values())
        for setups in (TWO_SETUPS, SIX_SETUPS):
            if names == _names(setups):
                return setups
        raise ValueError(f"gauges {', '.join(names)} are those of no setups "
                         f"(A, B or A..F)")

    def config(self) -> dict[str, Any]:
        """What this station's hardware is, in station.toml's shape: the machine's
        geometry, the controller's link and limits, the gauges' ports, protocol and
        strokes, and where they are mounted (its setups). The procedure and the
        write-back are the station's to choose (station.commands.simulate.launch).

        The drive's map is named ``profile`` (or the map's name), with the map's
        default unit id and, for a map without soft-limit registers, the limits the
        drive enforces as ``soft_min``/``soft_max``."""
        g = self.geometry
        ctl = self.controller
        # A map without soft-limit registers: the config tells the station the limits
        # the drive enforces, so that it can plan.
        limits = {} if ctl.map.has_role("SOFT_MIN") else {
            "soft_min": [float(v) for v in ctl.soft_min],
            "soft_max": [float(v) for v in ctl.soft_max]}
        return {
            "machine": {"leg_length": g.leg_length, "rho_min": g.rho_min, "rho_max": g.rho_max},
            # TCP: host and port; RTU: the pty the client opens and its baud rate.
            "controller": {**ctl.client_kwargs(), "profile": self.profile or ctl.map.name,
                           "device_id": ctl.device_id, **limits,
                           "timeout_s": CONTROLLER_TIMEOUT_S,
                           "speed_mm_s": self.speed_mm_s, "accel_mm_s2": self.accel_mm_s2,
                           # What an integrator would write: that the drive interpolates,
                           # if it does; else nothing (the profile's default: any timing).
                           # Never the drive's shape, delays or own acceleration.
                           **({"motion": "coordinated"} if self.machine.drive.coordinated
                              else {})},
            "indicators": [{"name": n, "port": s.port, "protocol": self.protocol,
                            "stroke_mm": self.strokes[n][0], "preload_mm": self.strokes[n][1]}
                           for n, s in self.indicators.items()],
            "setups": [dict(s) for s in self.setups],
            **({"joints": {"station_test": list(self.joint_gauges),
                           "station_gauge": dict(self.joint_gauges), "reference": STEP_GAUGE}}
               if self.joint_gauges else {}),
            "uncertainty": self.stated_inputs(),
        }

    def stated_inputs(self) -> dict[str, Any]:
        """What a shop that measured this machine would state of it ([uncertainty]):
        each leg's straightness, its bow's sagitta measured to half a micrometre (the
        virtual legs bow as the simulation says), and a room held within a tenth of a
        degree (the virtual machine does not warm). The gauges' MPE and the plungers'
        angle are left at the station's defaults, as a shop that has not measured
        them would. Its screws: each joint's positioning error within the bound a shop
        that measured them would state (:func:`joint_bound_um_per_m`; a joint the
        station tests itself takes its table)."""
        bows = [max(abs(float(b)), 0.0) + STRAIGHTNESS_READ_MM
                for b in self.machine.leg_bow]
        screws = self.machine.screws
        return {"leg_straightness_mm": [round(b, 6) for b in bows],
                "temperature_change_c": ROOM_HELD_C,
                "joint_positioning_um_per_m": joint_bound_um_per_m(
                    screws.lead_um_per_m, screws.pitch_um, screws.pitch_period_mm)}
