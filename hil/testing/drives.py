"""A drives-only bench in the test's own process: the simulated drives and plant of a bus
config, and a python-can bus per CAN bus for the master under test.

What ``hil sim`` runs, without a process, a port or a host: the user's master (canopen, an
ODrive or MIT client library, their own code) joins the bench's buses and drives the
joints as it would drive the real ones::

    with DrivesBench("ur3", lock_step=True) as bench:
        network = canopen.Network(bench.bus("arm"))
        ...                               # the master's own bring-up and commands
        bench.step(500)                   # lock-step: one second of the plant
        assert bench.joint("shoulder_lift_joint") == pytest.approx(-1.0, abs=1e-3)

Real time (the default): the plant follows the wall clock, as on a bench. Lock-step: the
plant advances one cycle when every drive of the config has had its cycle's frame (the
master's SYNC on every CiA 402 bus, a command to every other drive), or when the test calls
:meth:`DrivesBench.step`, which closes the cycle whatever the master sent; answers to a
cycle's frames leave after its step, as on the real bus they follow the SYNC.

Lock-step is lossless: the drives' side of each bus is ``hil-virtual``, which takes a frame
from the master's python-can ``virtual`` bus in the master's own thread (no Notifier between
them), so a frame whose ``send`` returned before ``step()`` is in that step's cycle, and the
answers are in the master's bus when ``step()`` returns. (Read by a Notifier thread, a step
closed the cycle before the drives had its frames: 97 answers to 1,001 MIT commands.) Over
SocketCAN (``vcan``) the kernel carries the frames, and a step cannot know what is in flight.
"""

from __future__ import annotations

import threading
import uuid
from dataclasses import dataclass
from pathlib import Path

import can

from hil.bus_config import DriveConfig, SystemConfig, config_path, load_bus_config, open_buses
from hil.can.faults import DRIVE_FAULT_WORDS, DriveFaultKind
from hil.can.monitor import NumberedChannels
from hil.description import PackagePath
from hil.errors import HilError
from hil.file_names import file_stem
from hil.realtime import LOCK_STEP, REAL_TIME
from hil.resources import BUS_CONFIGS, data_dir
from hil.simulator import Simulator
from hil.zenoh_session import ZenohSettings

#: python-can's in-process interface: a master joins with ``can.Bus(interface="virtual",
#: channel=bench.channel(name))`` or takes :meth:`DrivesBench.bus`
INTERFACE = "virtual"
#: the drives' side of those channels: hil's ``virtual``, which takes a master's frame in the
#: master's thread (the module doc)
DRIVES_INTERFACE = "hil-virtual"
#: the fault kinds :meth:`DrivesBench.fault` injects, as ``hil sim --fault`` names them
FAULT_KINDS = DRIVE_FAULT_WORDS


@dataclass(frozen=True)
class DriveInfo:
    """What a master needs of one joint's drive: where it is and its units."""

    bus: str
    channel: str
    #: the config's (255: none, until an LSS master gives one; the drive is named by its
    #: joint, which LSS does not change)
    node_id: int
    protocol: str
    #: joint to motor: the motor turns ``reduction`` radians per radian of the joint
    reduction: float
    #: encoder counts per motor revolution (CiA 402 positions are in these)
    counts_per_rev: int
    config: DriveConfig


class DrivesBench:
    """A bus config's drives and plant in this process, for a master to drive.

    ``config``: a bus config path or a robot's name (``ur3``: ``bus_config/ur3.yaml`` here,
    else the one hil ships). Every bus is python-can's ``virtual`` interface on a channel
    of its own (:meth:`channel`), whatever the config says; or, with ``vcan`` (bus name ->
    SocketCAN interface, e.g. ``{"arm": "vcan0"}``), those SocketCAN interfaces, for a
    master that opens SocketCAN itself."""

    def __init__(self, config: str | Path | SystemConfig, *, lock_step: bool = False,
                 package_path: PackagePath | None = None, vcan: dict[str, str] | None = None):
        if not isinstance(config, SystemConfig):
            config = load_bus_config(config_path(str(config)), package_path)
        self.config = config
        tag = uuid.uuid4().hex[:8]
        if vcan is not None and set(vcan) != {bus.name for bus in config.buses}:
            raise HilError.single(f"vcan names {', '.join(sorted(vcan)) or 'no bus'}",
                                  hint="give every bus of the config a SocketCAN interface: "
                                       f"{', '.join(bus.name for bus in config.buses)}")
        self.interface = INTERFACE if vcan is None else "socketcan"
        self.channels = dict(vcan) if vcan is not None else {
            bus.name: f"hil-bench-{tag}-{bus.name}" for bus in config.buses}
        self._sim_buses = open_buses(config, ZenohSettings.meeting(),
                                     DRIVES_INTERFACE if vcan is None else self.interface,
                                     self.channels)
        self.sim = Simulator(config, self._sim_buses, LOCK_STEP if lock_step else REAL_TIME)
        self.sim.start()
        self._thread = threading.Thread(target=self.sim.run, name="hil-drives-bench",
                                        daemon=True)
        self._thread.start()
        self._masters: list[can.BusABC] = []
        self._logs: list[tuple[can.Notifier, can.BusABC]] = []
        self._stepped_at = 0           # the plant's cycles when the last step() returned
        self._closed = False

    # --- the master's side --------------------------------------------------------------

    def channel(self, bus: str) -> str:
        """The channel of a bus of the config (python-can ``virtual``, or its vcan)."""
        try:
            return self.channels[bus]
        except KeyError:
            raise HilError.single(f"no bus '{bus}' in {self.config.path}",
                                  hint=f"buses: {', '.join(self.channels)}") from None

    def bus(self, name: str | None = None) -> can.BusABC:
        """A python-can bus on a bus of the config (the only one if ``name`` is None), for
        the master; shut down with the bench."""
        if name is None:
            if len(self.channels) != 1:
                raise HilError.single(f"{self.config.path} has buses "
                                      f"{', '.join(self.channels)}", hint="name one")
            name = next(iter(self.channels))
        opened = can.Bus(interface=self.interface, channel=self.channel(name))
        self._masters.append(opened)
        return opened

    def drive(self, joint: str) -> DriveInfo:
        """Where the drive of ``joint`` is and its units."""
        for bus in self.config.buses:
            for drive in bus.drives:
                if joint in drive.joints:
                    return DriveInfo(bus.name, self.channels[bus.name], drive.node_id,
                                     drive.protocol, self.config.robot.reduction(drive.actuator),
                                     drive.encoder_counts_per_rev, drive)
        raise HilError.single(f"no drive moves joint '{joint}' in {self.config.path}",
                              hint=f"joints: {', '.join(self.joints())}")

    def log_to(self, folder: Path) -> list[Path]:
        """Log every frame of every bus, from now until :meth:`close`, to ``folder/BUS.blf``
        (python-can's BLF, as ``hil replay`` reads); the files' paths."""
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for name, channel in self.channels.items():
            listener = can.Bus(interface=self.interface, channel=channel)
            path = folder / f"{file_stem(name)}.blf"   # a name over NAME_MAX: cut
            # channel 0 as python-can reads it back: what a name without digits got before
            # (a name's trailing digits became a number too large for BLF's 16 bits)
            log = NumberedChannels(can.Logger(path), {channel: 0})
            self._logs.append((can.Notifier(listener, [log]), listener))
            paths.append(path)
        return paths

    @staticmethod
    def eds() -> Path:
        """The EDS of hil's CiA 402 drives (object dictionary and default PDO mapping)."""
        return data_dir(BUS_CONFIGS) / "cia402_drive.eds"

    # --- the plant ---------------------------------------------------------------------

    def joints(self) -> dict[str, float]:
        """Every joint's position (rad or m) by name, now."""
        with self.sim.lock:
            positions = self.sim.plant.joint_positions().tolist()
        return dict(zip(self.sim.plant.joint_names, positions))

    def joint(self, name: str) -> float:
        """One joint's position (rad or m), now."""
        joints = self.joints()
        if name not in joints:
            raise HilError.single(f"no joint '{name}' in {self.config.path}",
                                  hint=f"joints: {', '.join(joints)}")
        return joints[name]

    def step(self, cycles: int = 1) -> None:
        """Lock-step: close ``cycles`` cycles now, each one control period of the plant, and
        send the drives' answers; HilError in real time (the wall clock steps it).

        The first is the cycle of the frames sent since the last step: where they closed it
        themselves (a frame to every drive), it counts, and ``cycles - 1`` more close. So a
        master that commands every drive and steps gets one period a step, as one that
        commands some of them does (hil's choice: the bench's cycle is the master's)."""
        if not self.sim.lock_step:
            raise HilError.single("step() advances a lock-step bench",
                                  hint="DrivesBench(config, lock_step=True)")
        with self.sim.lock:
            closed = self.sim.cycles > self._stepped_at and not self.sim.cycle_begun()
        for _ in range(cycles - closed):
            self.sim.close_cycle()
        self._stepped_at = self.sim.cycles

    def fault(self, joint: str, kind: str = "fault") -> None:
        """Inject a fault into the drive of ``joint``, as ``hil sim --fault KIND:...``: a
        drive fault (a following error, reported in the drive's protocol), ``silence`` (it
        leaves the bus) or ``restart`` (a power cycle)."""
        if kind not in FAULT_KINDS:
            raise HilError.single(f"no fault kind '{kind}'",
                                  hint=f"one of: {', '.join(FAULT_KINDS)}")
        self.sim.inject(DriveFaultKind(kind), self.sim.configured(self.drive(joint).config))

    def state(self, joint: str) -> str:
        """The drive's state in its protocol's words (``OPERATION ENABLED``, ``FAULT``, ...)."""
        drive = self.sim.configured(self.drive(joint).config)     # by its entry: LSS ids move
        with self.sim.lock:
            return drive.state_text

    def freeze(self) -> None:
        """Stop the plant's clock (idempotent): the plant stands where it is and the drives
        answer from it, without timed messages or watchdogs, until :meth:`close`; for a
        master that reads back a state that no longer moves."""
        self.sim.stop()
        self._thread.join(5)

    # --- life cycle -------------------------------------------------------------------

    def close(self) -> None:
        """Drives disabled, the plant stopped, every bus shut down (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self.sim.stop()
        self._thread.join(5)
        self.sim.close()
        for notifier, _ in self._logs:
            notifier.stop()                # and its log: the file closed, its header written
        for bus in self._masters + [bus for _, bus in self._logs] + list(
                self._sim_buses.values()):
            bus.shutdown()

    def __enter__(self) -> DrivesBench:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
