"""The bus config's ``sensors:``: each sensor on a link of the robot, its product, its wire and
its errors, checked with its line.

Example (a WitMotion IMU on the pelvis, read at 200 Hz over a 460,800-baud serial port)::

    sensors:
      - name: imu
        product: wit
        link: pelvis
        port: /tmp/hil-imu
        baud: 460800
        rate_hz: 200
        gyroscope: {noise_density: 1.75e-4, bias_instability: 3.9e-5}
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field

from hil.bus_config.force_torque_entry import DEFAULT_POLL_HZ, FORCE_TORQUE_KEYS, read_force_torque
from hil.bus_config.sensor_types import ImuConfig, Sensor, TriadErrors
from hil.bus_config.sensor_values import read_errors, read_vector
from hil.bus_config.types import BusConfig
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import RobotDescription
from hil.protocols import dm_imu, hipnuc, wit

SERIAL, CAN = "serial", "can"
DEFAULT_BAUD = 9600
#: the chip WitMotion's WT901 is built on, InvenSense's MPU-9250 (product specification
#: rev. 1.1, tables 1 and 2): gyroscope rate noise 0.01 °/s/√Hz, accelerometer noise
#: 300 µg/√Hz. Its bias instability is not stated there: hil's choice, a MEMS part's
#: typical floor (gyroscope 10 °/h, accelerometer 0.1 mg). HiPNUC's figures are not in
#: hil's sources: the same defaults stand for its parts
DEFAULT_ERRORS = {
    "accelerometer": TriadErrors(noise_density=300e-6 * wit.G, bias_instability=0.1e-3 * wit.G),
    "gyroscope": TriadErrors(noise_density=math.radians(0.01),
                             bias_instability=math.radians(10 / 3600)),
}
#: the DM-IMU-L1's chip, Bosch's BMI088 (the manual: its figures are the chip's; the
#: BMI088 data sheet, table 1 and 2: accelerometer 160 µg/√Hz, gyroscope 0.014 °/s/√Hz);
#: its bias instability, as above, hil's choice
BMI088_ERRORS = {
    "accelerometer": TriadErrors(noise_density=160e-6 * wit.G, bias_instability=0.1e-3 * wit.G),
    "gyroscope": TriadErrors(noise_density=math.radians(0.014),
                             bias_instability=math.radians(10 / 3600)),
}


@dataclass(frozen=True)
class Product:
    """What a config may ask of a product family: its wire, outputs and rates."""

    wire: str                              # SERIAL or CAN
    outputs: dict[str, int]                # output name -> the codec's packet type or TPDO
    default_outputs: tuple[str, ...]
    default_rate: float                    # Hz
    rates: tuple[float, ...] = ()          # the rates it offers (none: any up to max_rate)
    max_rate: float = math.inf
    #: it answers requests (hil control polls it) rather than streaming
    polled: bool = False
    #: the angle one count of the orientation stands for, given its outputs (its codec's)
    orientation_step: Callable[[tuple[int, ...]], float] = wit.orientation_step
    #: its errors where the config sets none, by triad
    errors: dict[str, TriadErrors] = field(default_factory=lambda: DEFAULT_ERRORS)


#: the products hil serves, by the name a config gives (docs/sensors.md). WitMotion's
#: factory settings (its manual): 9600 baud, 10 Hz, the 0x51-0x53 packets (and the
#: magnetometer's, which hil does not model). HiPNUC's: every TPDO; its default rate is
#: hil's choice (the maker's code is silent). Damiao's DM-IMU-L1: the three registers its
#: sample code requests; it samples at its top rate (hil's choice: the manual gives none for
#: its request mode)
PRODUCTS = {
    "wit": Product(SERIAL, wit.OUTPUTS, ("acceleration", "angular_velocity", "angle"), 10.0,
                   rates=tuple(float(r) for r in wit.RATES_HZ)),
    "hipnuc": Product(CAN, hipnuc.OUTPUTS, tuple(hipnuc.OUTPUTS), 100.0,
                      max_rate=hipnuc.MAX_RATE_HZ, orientation_step=hipnuc.orientation_step),
    "dm_imu": Product(CAN, dm_imu.OUTPUTS, ("acceleration", "angular_velocity", "quaternion"),
                      1000.0, rates=dm_imu.RATES_HZ, polled=True,
                      orientation_step=dm_imu.orientation_step, errors=BMI088_ERRORS),
}
MAX_SENSORS = 32
#: the keys every sensor takes, and those of each kind and wire
_COMMON_KEYS = {"name", "product", "link", "xyz", "rpy", "seed"}
_IMU_KEYS = {"rate_hz", "outputs", "latency", "accelerometer", "gyroscope"}
_WIRE_KEYS_OF = {SERIAL: {"port", "baud"}, CAN: {"bus", "node_id"}}
_POLLED_KEYS = {"master_id", "firmware", "poll_hz"}
#: the force-torque product (its own module: hil.bus_config.force_torque_entry)
FORCE_TORQUE = "ati_netft"
_KEYS_OF = {**{name: _COMMON_KEYS | _IMU_KEYS | _WIRE_KEYS_OF[product.wire]
               | (_POLLED_KEYS if product.polled else set())
               for name, product in PRODUCTS.items()},
            FORCE_TORQUE: _COMMON_KEYS | FORCE_TORQUE_KEYS}
_KEYS = set().union(*_KEYS_OF.values())
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,63}")


def read_sensors(reader: Reader, top: LineMapping, robot: RobotDescription,
                 buses: tuple[BusConfig, ...]) -> tuple[Sensor, ...]:
    """The ``sensors:`` list (none: no sensor); a CAN sensor on one of ``buses``."""
    if "sensors" not in top:
        return ()
    raw = top["sensors"]
    line = top.key_lines.get("sensors", top.line)
    if not isinstance(raw, list) or len(raw) > MAX_SENSORS:
        reader.fail(f"'sensors' must be a list of at most {MAX_SENSORS} sensors "
                    "({name: ..., product: wit, link: ..., ...})", line)
        return ()
    links = {link.name for link in robot.links}
    by_name = {bus.name: bus for bus in buses}
    sensors = tuple(s for s in (_read_sensor(reader, item, number + 1, line, robot.name, links,
                                             by_name)
                                for number, item in enumerate(raw)) if s is not None)
    polled = [s for s in sensors if isinstance(s, ImuConfig) and s.master_id is not None]
    for sensor in polled:
        if [(s.bus, s.node_id) for s in polled].count((sensor.bus, sensor.node_id)) > 1:
            reader.fail(f"sensor '{sensor.name}': another DM-IMU on bus '{sensor.bus}' has its "
                        f"node_id {sensor.node_id}: a request to one is a request to both",
                        sensor.line, hint="give every DM-IMU on a bus its own node_id")
    for kind in ("name", "port"):
        seen = [getattr(s, kind, None) for s in sensors]
        for sensor in sensors:
            if getattr(sensor, kind, None) is not None and seen.count(getattr(sensor, kind)) > 1:
                reader.fail(f"sensor '{sensor.name}': another sensor has its {kind} "
                            f"'{getattr(sensor, kind)}'", sensor.line,
                            hint=f"give every sensor its own {kind}")
    return sensors


def _read_sensor(reader: Reader, raw, number: int, list_line: int | None, robot: str,
                 links: set[str], buses: dict[str, BusConfig]) -> Sensor | None:
    item = reader.mapping(raw, f"sensor {number}", list_line)
    if not item:
        return None
    reader.unknown_keys(item, _KEYS, f"sensor {number}")
    name = reader.text(item, "name", f"sensor {number}", f"sensor{number}")
    what = f"sensor '{name}'"
    if not _NAME.fullmatch(name):
        reader.fail(f"{what}: a name is a letter, then letters, digits, '_' or '-' (at most "
                    "64)", item.key_lines.get("name", item.line))
    product_name = reader.text(item, "product", what, "")
    if product_name not in _KEYS_OF:
        reader.fail(f"{what}: unknown product {product_name!r}",
                    item.key_lines.get("product", item.line),
                    hint=f"products hil serves: {', '.join(_KEYS_OF)} (docs/sensors.md)")
        return None
    for key in sorted(set(item) & (_KEYS - _KEYS_OF[product_name])):
        reader.fail(f"{what}: '{key}' is not for a {product_name} sensor",
                    item.key_lines.get(key, item.line),
                    hint=f"it takes {', '.join(sorted(_KEYS_OF[product_name]))}")
    link = reader.text(item, "link", what, "")
    if link and link not in links:
        reader.fail(f"{what}: the robot has no link '{link}'",
                    item.key_lines.get("link", item.line),
                    hint="'link' names a link of the robot's description (hil describe lists "
                         "them)")
    if product_name == FORCE_TORQUE:
        return read_force_torque(reader, item, what, name, link, buses)
    product = PRODUCTS[product_name]
    rate = float(reader.number(item, "rate_hz", what, product.default_rate))
    if (rate not in product.rates) if product.rates else rate > product.max_rate:
        offered = (f"one of {', '.join(f'{r:g}' for r in product.rates)}" if product.rates
                   else f"at most {product.max_rate:g} Hz")
        reader.fail(f"{what}: 'rate_hz' {rate:g} is none the product offers",
                    item.key_lines.get("rate_hz", item.line), hint=offered)
    outputs = _read_outputs(reader, item, what, product)
    codes = tuple(product.outputs[o] for o in outputs)
    latency = float(reader.number(item, "latency", what, 0.0, positive=False))
    if not 0 <= latency <= 1:
        reader.fail(f"{what}: 'latency' is 0 to 1 s, not {latency:g}",
                    item.key_lines.get("latency", item.line))
    if product.wire == SERIAL:
        wire = _read_serial(reader, item, what, rate, outputs, robot, name)
    elif product.polled:
        wire = _read_dm_imu(reader, item, what, buses)
    else:
        wire = _read_can(reader, item, what, buses)
    return ImuConfig(
        name=name, product=product_name, link=link,
        xyz=read_vector(reader, item, "xyz", what, 10.0),
        rpy=read_vector(reader, item, "rpy", what, 2 * math.pi),
        **wire, rate_hz=rate, outputs=codes, latency=max(latency, 0.0),
        orientation_step=product.orientation_step(codes),
        accelerometer=read_errors(reader, item, "accelerometer", what,
                                  product.errors["accelerometer"]),
        gyroscope=read_errors(reader, item, "gyroscope", what, product.errors["gyroscope"]),
        seed=int(reader.number(item, "seed", what, 0, positive=False, integer=True)),
        line=item.line)


def _read_serial(reader: Reader, item: LineMapping, what: str, rate: float,
                 outputs: tuple[str, ...], robot: str, name: str) -> dict:
    """A serial sensor's port and baud rate, checked to carry its stream."""
    baud = int(reader.number(item, "baud", what, DEFAULT_BAUD, integer=True))
    if baud not in wit.BAUD_RATES:
        reader.fail(f"{what}: 'baud' {baud} is none the product offers",
                    item.key_lines.get("baud", item.line),
                    hint=f"one of {', '.join(map(str, wit.BAUD_RATES))}")
    needed = wit.bits_per_second(rate, outputs)
    if baud in wit.BAUD_RATES and needed > baud:
        reader.fail(f"{what}: {len(outputs)} packets at {rate:g} Hz take {needed:,.0f} bit/s, "
                    f"more than {baud} baud carries",
                    item.key_lines.get("baud", item.line),
                    hint="raise 'baud', lower 'rate_hz' or send fewer 'outputs' (as the "
                         "product would lose samples)")
    # like 'robot', relative to the config's folder: two benches from two folders never
    # share a port (hil init writes one beside its config)
    port = reader.path.parent.absolute() / reader.text(item, "port", what,
                                                       f"/tmp/hil-{robot}-{name}")
    return {"port": port, "baud": baud}


def _read_can(reader: Reader, item: LineMapping, what: str, buses: dict[str, BusConfig]
              ) -> dict:
    """A CAN sensor's bus and node id: a classical CAN node, on a bus of the config."""
    bus = _read_bus(reader, item, what, buses)
    node_id = int(reader.number(item, "node_id", what, hipnuc.DEFAULT_NODE_ID, integer=True))
    if not 1 <= node_id <= 127:
        reader.fail(f"{what}: 'node_id' is 1 to 127 (CANopen), not {node_id}",
                    item.key_lines.get("node_id", item.line))
    return {"bus": bus, "node_id": node_id}


def _read_dm_imu(reader: Reader, item: LineMapping, what: str,
                 buses: dict[str, BusConfig]) -> dict:
    """A DM-IMU's bus, CAN id, master id, firmware and poll rate: its bus at the 1 Mbit/s
    its firmware speaks, its ids the one-byte values its setting commands take."""
    bus = _read_bus(reader, item, what, buses)
    if bus in buses and buses[bus].bitrate != dm_imu.BITRATE:
        reader.fail(f"{what}: bus '{bus}' runs at {buses[bus].bitrate:,} bit/s; a DM-IMU-L1 "
                    f"speaks {dm_imu.BITRATE:,} only (its firmware cannot change it)",
                    item.key_lines.get("bus", item.line),
                    hint=f"put it on a bus of bitrate: {dm_imu.BITRATE}")
    ids = {}
    for key, default, lowest in (("node_id", dm_imu.DEFAULT_NODE_ID, 1),
                                 ("master_id", dm_imu.DEFAULT_MASTER_ID, 0)):
        ids[key] = int(reader.number(item, key, what, default, integer=True, positive=False))
        if not lowest <= ids[key] <= 0xFF:
            reader.fail(f"{what}: '{key}' is {lowest} to 255 (one byte, as the IMU's setting "
                        f"command takes it), not {ids[key]}", item.key_lines.get(key, item.line))
    if ids["node_id"] == ids["master_id"]:
        reader.fail(f"{what}: 'master_id' is its 'node_id' ({ids['node_id']}): its answers "
                    "would come on its requests' id", item.key_lines.get("master_id", item.line),
                    hint=f"the maker's example: node_id {dm_imu.DEFAULT_NODE_ID}, master_id "
                         f"0x{dm_imu.DEFAULT_MASTER_ID:02X}")
    firmware = int(reader.number(item, "firmware", what, dm_imu.DEFAULT_FIRMWARE,
                                 integer=True))
    if firmware not in dm_imu.FIRMWARES:
        reader.fail(f"{what}: 'firmware' {firmware} is none hil knows",
                    item.key_lines.get("firmware", item.line),
                    hint="1022 (the manual V1.1's protocol: requests at 0x6FF), 1023 "
                         "(requests at its CAN id, ±24 g) or 1024 (8-byte requests)")
        firmware = dm_imu.DEFAULT_FIRMWARE
    poll = float(reader.number(item, "poll_hz", what, DEFAULT_POLL_HZ))
    if bus in buses and poll > buses[bus].cycle_hz:
        reader.fail(f"{what}: 'poll_hz' {poll:g} is over its bus' cycle rate "
                    f"({buses[bus].cycle_hz:g} Hz): hil control requests at most once a cycle",
                    item.key_lines.get("poll_hz", item.line))
    return {"bus": bus, **ids, "firmware": firmware, "poll_hz": poll}


def _read_bus(reader: Reader, item: LineMapping, what: str, buses: dict[str, BusConfig]
              ) -> str:
    """A CAN sensor's bus: a classical bus of the config."""
    bus = reader.text(item, "bus", what, "")
    if bus and bus not in buses:
        reader.fail(f"{what}: the config has no bus '{bus}'", item.key_lines.get("bus",
                                                                                  item.line),
                    hint=f"buses: {', '.join(buses)}")
    elif bus and buses[bus].fd:
        reader.fail(f"{what}: a classical CAN device on FD bus '{bus}', whose FD frames it "
                    "would answer with error frames", item.key_lines.get("bus", item.line),
                    hint="put it on a classical bus (no fd: true)")
    return bus


def _read_outputs(reader: Reader, item: LineMapping, what: str,
                  product: Product) -> tuple[str, ...]:
    value = item.get("outputs", list(product.default_outputs))
    if (not isinstance(value, list) or not value or len(set(value)) != len(value)
            or not all(v in product.outputs for v in value)):
        reader.fail(f"{what}: 'outputs' is a list of {', '.join(product.outputs)}, each once, "
                    f"not {value!r}", item.key_lines.get("outputs", item.line))
        return product.default_outputs
    return tuple(value)
