"""Each joint's positioning error for TwinCAT CNC (docs/design.md, "Joint tables in the
controller"): one leadscrew error compensation list (LSEC, ``kw.ssfk.*``) per axis
that has a table. Pure: from a table to text.

The list, as Beckhoff's TwinCAT CNC documentation gives it (TF5200 "Axis
compensation", "Leadscrew error compensation (kw.ssfk.*)" and its "Example of a
compensation value list"): a header ``kopf.achs_nr`` (the axis' logical number) and
``kopf.log_achs_name``; ``kw.ssfk.unit 1`` (lengths metric, in 0.1 µm),
``kw.ssfk.interval 0`` (each interpolation point given), ``kw.ssfk.kw_startpos``,
``kw.ssfk.kw_nr_max`` (the number of entries), ``kw.ssfk.bilateral 1`` (one table per
direction); then per entry i ``kw.ssfk.table[i].setpoint`` (the axis position),
``.pos`` and ``.neg``: the position error Δs = s_actual − s_setpoint measured moving in
the positive (negative) direction, which the CNC takes off the position setpoint.
That is the ISO 230-2 deviation as the shop's test gives it, so the list carries ε
itself (orthocal's sign: actual − target), in 0.1 µm, rounded. Comment lines start
with ``#``. The axis' parameter P-AXIS-00175 (``lr_param.ssfk 1``) switches the
compensation on.
"""

from __future__ import annotations

from collections.abc import Sequence

from station.history.controller_terms import ExportError
from station.record.controller_tables import ControllerJoint

#: TwinCAT CNC's entries per list unless its P-COMP-00059 says otherwise.
MAX_ENTRIES = 1500
_TENTH_UM = 1e4  # 0.1 µm per mm


def lsec_file_name(axis: str) -> str:
    """The list of joint ``axis``."""
    return f"orthocal-lsec-{axis}.lis"


def _units(mm: float) -> int:
    return round(mm * _TENTH_UM)


def lsec_list(joint: ControllerJoint, nc_axis: str, number: int,
              header: Sequence[str]) -> str:
    """The compensation list of ``joint`` for the CNC axis named ``nc_axis`` (logical
    number ``number``), under ``header`` (the export's comment lines)."""
    table = joint.table
    if table is None:
        raise ValueError(f"joint {joint.axis} has no table")
    n = len(table.targets_mm)
    if n > MAX_ENTRIES:
        raise ExportError(f"joint {joint.axis}: its table has {n} targets; TwinCAT CNC takes "
                          f"{MAX_ENTRIES} per list unless kw.ssfk.max_points says more")
    setpoints = [_units(v) for v in table.targets_mm]
    lines = [
        *header,
        f"# {lsec_file_name(joint.axis)}: leadscrew error compensation list (kw.ssfk) of "
        f"joint {joint.axis}, {joint.describe()}, referred to Pi0.",
        "# setpoint: the axis position in 0.1 um, where the NC counts the joint as the",
        "#   station commands it (absolute, Pi0 at rho = L) with the offsets the run",
        f"#   wrote: the test's targets moved by {joint.shift_mm:+.6f} mm. Where the NC "
        "counts",
        "#   from another zero, add (its position at Pi0 - L) to every setpoint.",
        "# pos / neg: the position error actual - setpoint (ISO 230-2) moving in the",
        "#   positive / negative direction, in 0.1 um; the CNC takes it off the setpoint.",
        "# Switch it on with the axis parameter lr_param.ssfk 1 (P-AXIS-00175).",
        f"kopf.achs_nr                 {number}",
        f"kopf.log_achs_name           {nc_axis}",
        "kw.ssfk.unit                 1",
        "kw.ssfk.interval             0",
        f"kw.ssfk.kw_startpos          {setpoints[0]}",
        f"kw.ssfk.kw_nr_max            {n}",
        "kw.ssfk.bilateral            1",
    ]
    lines += [f"kw.ssfk.table[{i}].setpoint    {s}" for i, s in enumerate(setpoints)]
    lines += [f"kw.ssfk.table[{i}].pos    {_units(v)}" for i, v in enumerate(table.forward_mm)]
    lines += [f"kw.ssfk.table[{i}].neg    {_units(v)}" for i, v in enumerate(table.reverse_mm)]
    return "\n".join(lines) + "\n"


def lsec_lists(joints: Sequence[ControllerJoint], nc_axes: Sequence[str],
               header: Sequence[str]) -> dict[str, str]:
    """File name → list of every joint with a table; the CNC axes named ``nc_axes``
    (x, y, z), numbered 1, 2, 3."""
    return {lsec_file_name(j.axis): lsec_list(j, nc_axes[i].strip(), i + 1, header)
            for i, j in enumerate(joints) if j.table is not None}
