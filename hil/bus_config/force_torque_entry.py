"""A force-torque sensor's entry of the bus config's ``sensors:`` (ATI's Net F/T on CAN):
its bus and base identifier, its calibration and its errors, checked with their lines.

Example (a Net F/T on the wrist bus, its base identifier 0x10)::

    sensors:
      - {name: wrist_ft, product: ati_netft, link: hand, bus: wrist, base_id: 0x10}
"""

from __future__ import annotations

import math

from hil.bus_config.sensor_types import ForceTorqueConfig, TriadErrors
from hil.bus_config.sensor_values import read_errors, read_vector
from hil.bus_config.types import BusConfig
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.protocols import ati_netft

FORCE_TORQUE_KEYS = {"bus", "base_id", "counts_per_force", "counts_per_torque",
                     "short_divisors", "force", "torque", "poll_hz"}
#: how often hil control requests long data unless told (hil's choice: a wrench controller's
#: usual rate; the bus' cycle rate at most)
DEFAULT_POLL_HZ = 100.0
#: a Net F/T's calibration as hil assumes it unless told: counts per N and per N·m (the
#: Ethernet interface's calibration record carries them; ATI's example calibrations give
#: 1,000,000), and the 16-bit short data's divisors (hil's choice: 1 mN and 0.1 mN·m a
#: count, ±32.7 N and ±3.27 N·m)
DEFAULT_COUNTS = 1_000_000.0
DEFAULT_SHORT_DIVISORS = (1000.0, 100.0)
#: the noise of a small F/T transducer, hil's choice where the config sets none (ATI
#: states resolutions per transducer and calibration, not a noise density): 2 mN and
#: 0.05 mN·m per sample at its internal rate
SAMPLE_HZ = 7000.0
DEFAULT_FORCE = TriadErrors(noise_density=0.002 / math.sqrt(SAMPLE_HZ))
DEFAULT_TORQUE = TriadErrors(noise_density=0.00005 / math.sqrt(SAMPLE_HZ))


def read_force_torque(reader: Reader, item: LineMapping, what: str, name: str, link: str,
                      buses: dict[str, BusConfig]) -> ForceTorqueConfig:
    """The entry of a Net F/T on one of ``buses``."""
    bus = reader.text(item, "bus", what, "")
    if bus and bus not in buses:
        reader.fail(f"{what}: the config has no bus '{bus}'",
                    item.key_lines.get("bus", item.line), hint=f"buses: {', '.join(buses)}")
    poll = float(reader.number(item, "poll_hz", what, DEFAULT_POLL_HZ))
    if bus in buses and poll > buses[bus].cycle_hz:
        reader.fail(f"{what}: 'poll_hz' {poll:g} is over its bus' cycle rate "
                    f"({buses[bus].cycle_hz:g} Hz): hil control requests at most once a cycle",
                    item.key_lines.get("poll_hz", item.line))
    base_id = int(reader.number(item, "base_id", what, None, integer=True, positive=False))
    if not 0 <= base_id <= ati_netft.MAX_BASE_ID:
        reader.fail(f"{what}: 'base_id' is 0 to 0x{ati_netft.MAX_BASE_ID:X} (its answers go "
                    f"to base_id + 1 ... + 6, 11-bit identifiers), not {base_id}",
                    item.key_lines.get("base_id", item.line))
    divisors = item.get("short_divisors", list(DEFAULT_SHORT_DIVISORS))
    if (not isinstance(divisors, list) or len(divisors) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) and v > 0 for v in divisors)):
        reader.fail(f"{what}: 'short_divisors' is [forces, torques], two numbers > 0 (long "
                    f"counts per short count), not {divisors!r}",
                    item.key_lines.get("short_divisors", item.line))
        divisors = list(DEFAULT_SHORT_DIVISORS)
    return ForceTorqueConfig(
        name=name, product="ati_netft", link=link,
        xyz=read_vector(reader, item, "xyz", what, 10.0),
        rpy=read_vector(reader, item, "rpy", what, 2 * math.pi),
        bus=bus, base_id=base_id,
        counts_per_force=float(reader.number(item, "counts_per_force", what, DEFAULT_COUNTS)),
        counts_per_torque=float(reader.number(item, "counts_per_torque", what,
                                              DEFAULT_COUNTS)),
        short_divisors=(float(divisors[0]), float(divisors[1])),
        force=read_errors(reader, item, "force", what, DEFAULT_FORCE),
        torque=read_errors(reader, item, "torque", what, DEFAULT_TORQUE),
        sample_hz=SAMPLE_HZ, poll_hz=poll,
        seed=int(reader.number(item, "seed", what, 0, positive=False, integer=True)),
        line=item.line)
