"""What ``hil describe`` prints of hil's CiA 402 drives once, after the buses: the EDS a
master reads and the default PDO mapping in it."""

from __future__ import annotations

import canopen

from hil.resources import eds_path

#: the PDO mapping objects of the EDS and the PDO each maps (CiA 301 7.5.2.36, 7.5.2.38)
PDO_MAPS = {0x1600: "RPDO1", 0x1601: "RPDO2", 0x1602: "RPDO3", 0x1603: "RPDO4",
            0x1A00: "TPDO1", 0x1A01: "TPDO2", 0x1A02: "TPDO3", 0x1A03: "TPDO4"}


def dictionary_summary() -> list[str]:
    """The EDS' path and units, and each PDO's default mapping, one line each."""
    path = eds_path()
    od = canopen.import_od(str(path))
    lines = [f"CiA 402 drives: object dictionary and default PDO mapping {path} (canopen, "
             "ros2_canopen and PLCs read it); units: positions in encoder counts, velocities "
             "in counts/s, torques in per mille of the rated torque (0x6076)"]
    for index, pdo in PDO_MAPS.items():
        if index not in od:
            continue
        record = od[index]
        mapped = []
        for sub in range(1, (record[0].default or 0) + 1):
            entry = record[sub].default
            target = od.get_variable(entry >> 16, (entry >> 8) & 0xFF)
            mapped.append(f"0x{entry >> 16:04X} {target.name if target else '?'}")
        lines.append(f"  {pdo}: {', '.join(mapped) or '(none mapped)'}")
    return lines
