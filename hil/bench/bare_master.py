"""``hil bench``, scale: ``hil sim``'s drives in front of a bare python-can master, beside
``hil control``'s figures, so that the sweep tells what hil's own master costs over the
least any master needs.

The bare master is this process: python-can on the Zenoh transport and the floor's paced
loop (:func:`hil.bench.floor.run_paced_master`: a cycle's frames sent together, as ``hil
control`` sends them, its answers awaited). It brings each CiA 402 drive up as a minimal
master following CiA 301/402 would: NMT start (all nodes), cyclic synchronous position
(0x6060 = 8) by an expedited SDO download; then each cycle RPDO1 (controlword, target
position) and the SYNC, answered by TPDO1 (statusword, position) and TPDO2. The controlword
walks each drive up to OPERATION ENABLED as its statusword says (the controlwords hil's
master sends: :data:`hil.protocols.cia402.axis.WALK_UP`), the target always the drive's last
reported position: it holds where it is, with no trajectory, no feed-forward and no fault
handling.

Damiao motors (the sweep's robots at 1 kHz, on CAN FD buses as OpenArm's) are brought up as
the maker's sample code and python ``damiao-motor`` do: the enable frame (FF x7, FC) to each,
in the bus' frame format; then each cycle an MIT command holding the position its first
feedback reported, with the gains the bus config gives the master (``kp``, ``kd``), no
velocity and no feed-forward, answered by its feedback. A sweep's robot has drives of one
protocol; hil's other protocols are not driven.
"""

from __future__ import annotations

import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

import can

from hil.bench.floor import PacedMaster, run_paced_master
from hil.bench.settings import DID_NOT_START
from hil.bus_config import SystemConfig, load_bus_config
from hil.protocols.cia402 import Cia402
from hil.protocols.damiao import ENABLE, Damiao, State, unpack_feedback
from hil.protocols.mit.codec import MitRanges, pack_command_values
from hil.protocols.cia402.axis import RPDO1, SHUTDOWN, TPDO1, WALK_UP, state_of
from hil.realtime import real_time_cpus
from hil.supervisor import Child, ChildFailed, Run, cpus_argument
from hil.zenoh_session import free_loopback_port

#: NMT start remote node, to every node (CiA 301 7.2.8.3.1.1)
NMT_START_ALL = can.Message(arbitration_id=0x000, data=[0x01, 0x00], is_extended_id=False)
#: expedited SDO download of one byte to 0x6060:00, the value 8 (cyclic synchronous position)
SDO_CSP = bytes([0x2F, 0x60, 0x60, 0x00, 0x08, 0x00, 0x00, 0x00])
#: the first byte of an expedited download's answer (CiA 301 7.2.4.3.4)
SDO_DOWNLOADED = 0x60
#: how long the bring-up waits for every SDO answer (s)
BRING_UP_TIMEOUT = 5.0


def bare_master_across_processes(config_path: Path, seconds: float) -> dict:
    """One real-time run of ``hil sim`` on the config with the bare master (this process) in
    the controller's place, each on the CPU ``hil up`` gives the process it stands for: the
    master's paced figures, the round trip, each process' CPU share (``sim``, ``control``),
    and how many of its ``drives`` last reported OPERATION ENABLED (``enabled``). A sim that
    does not start is the row :data:`DID_NOT_START`."""
    config = load_bus_config(config_path)
    sim_cpus, control_cpus, _ = real_time_cpus()
    master = holding_master(config)
    with tempfile.TemporaryDirectory(prefix="hil-bench-bare-") as folder:
        endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
        sim = Child("sim", ["sim", str(config_path), "--listen", endpoint, "--status-period",
                            "0", *cpus_argument(sim_cpus)], Path(folder) / "sim.log")
        run = Run([sim])
        try:
            sim.start()
            run.wait_for_line(sim, "hil sim:")
            figures = run_paced_master(config, {bus.name: bus.channel for bus in config.buses},
                                       endpoint, seconds, control_cpus, True, sim.pid, master)
        except ChildFailed as failure:
            return {DID_NOT_START: str(failure)}
        finally:
            run.shut_down()
    return {**figures, "drives": master.drives, "enabled": master.enabled()}


def holding_master(config: SystemConfig) -> HoldingMaster | DamiaoHoldingMaster:
    """The bare master for the config's drives: Damiao's where every drive is a Damiao
    motor, else CiA 402's (which drives the CiA 402 drives among them)."""
    if all(drive.protocol == Damiao.name for bus in config.buses for drive in bus.drives):
        return DamiaoHoldingMaster(config)
    return HoldingMaster({bus.name: (bus.channel, [drive.node_id for drive in bus.drives
                                                   if drive.protocol == Cia402.name])
                          for bus in config.buses})


class HoldingMaster(PacedMaster):
    """Each TPDO1's statusword and position written into its drive's RPDO1 (the message the
    paced loop sends next), so that every drive walks up to enabled and holds there."""

    #: the drives walk up in three cycles; a second leaves the bring-up's stalls behind
    warm_up = 1.0

    def __init__(self, nodes: dict[str, tuple[str, list[int]]]):
        #: each bus' channel and CiA 402 drives' node ids, by bus name
        self.nodes = nodes
        self.drives = sum(len(node_ids) for _, node_ids in nodes.values())
        #: each drive's RPDO1 message (sent every cycle), by its bus' channel and its TPDO1's
        #: id (node ids repeat from bus to bus)
        self._rpdo1: dict[tuple[str, int], can.Message] = {}
        self._states: dict[tuple[str, int], str] = {}
        self._sdo_answers: set[tuple[str, int]] = set()
        self._answered = threading.Condition()

    def start(self, cycle: dict[str, tuple[can.BusABC, list[can.Message]]]) -> None:
        """NMT start to all, then 0x6060 = 8 on every drive, waiting for each answer."""
        wanted = set()
        for name, (bus, out) in cycle.items():
            channel, node_ids = self.nodes[name]
            self._rpdo1.update({(channel, message.arbitration_id - 0x200 + 0x180): message
                                for message in out
                                if message.arbitration_id - 0x200 in node_ids})
            bus.send(NMT_START_ALL)
            for node in node_ids:
                bus.send(can.Message(arbitration_id=0x600 + node, data=SDO_CSP,
                                     is_extended_id=False))
            wanted |= {(channel, 0x580 + node) for node in node_ids}
        with self._answered:
            if not self._answered.wait_for(lambda: wanted <= self._sdo_answers,
                                           BRING_UP_TIMEOUT):
                raise RuntimeError(f"the bare master's SDO writes of 0x6060 went unanswered "
                                   f"by {len(wanted - self._sdo_answers)} drives")

    def on_message_received(self, msg: can.Message) -> None:
        identifier = msg.arbitration_id
        rpdo1 = self._rpdo1.get((msg.channel, identifier))
        if rpdo1 is not None and len(msg.data) == TPDO1.size:
            statusword, position = TPDO1.unpack(msg.data)
            state = state_of(statusword)
            self._states[msg.channel, identifier] = state
            # one slice assignment: the paced loop never sends half of it
            rpdo1.data[:] = RPDO1.pack(WALK_UP.get(state, SHUTDOWN), position)
        elif 0x581 <= identifier <= 0x5FF and msg.data and msg.data[0] == SDO_DOWNLOADED:
            with self._answered:
                self._sdo_answers.add((msg.channel, identifier))
                self._answered.notify_all()

    def enabled(self) -> int:
        """How many drives last reported OPERATION ENABLED."""
        return sum(state == "OPERATION ENABLED" for state in self._states.values())


@dataclass
class _HeldMotor:
    """A Damiao motor as the bare master knows it: its ranges and gains, its bus and command
    id, and (once started) its command, the position it holds and its last state."""

    ranges: MitRanges
    kp: float
    kd: float
    bus: str
    command_id: int
    command: can.Message | None = None
    held: float | None = None
    state: State | None = None


class DamiaoHoldingMaster(PacedMaster):
    """Each Damiao motor enabled, then held by MIT commands at the position of its first
    feedback (the module doc); each feedback's state kept for :meth:`enabled`."""

    warm_up = 1.0

    def __init__(self, config: SystemConfig):
        #: each motor, by its bus' channel and the id it answers on
        self._motors = {
            (bus.channel, drive.options.reply_id(drive.node_id)): _HeldMotor(
                drive.options.ranges(), drive.options.kp, drive.options.kd, bus.name,
                drive.node_id + drive.options.control_mode.id_offset)
            for bus in config.buses for drive in bus.drives}
        self.drives = len(self._motors)

    def start(self, cycle: dict[str, tuple[can.BusABC, list[can.Message]]]) -> None:
        """The enable frame to every motor, in the format of its command (FD with BRS on an
        FD bus); until its first feedback its command asks no torque (all values 0: zero
        bytes would be each range's low end, the torque's -TMAX)."""
        for motor in self._motors.values():
            bus, out = cycle[motor.bus]
            (command,) = [m for m in out if m.arbitration_id == motor.command_id]
            command.data[:] = pack_command_values(0.0, 0.0, 0.0, 0.0, 0.0, motor.ranges)
            motor.command = command
            bus.send(can.Message(arbitration_id=motor.command_id, data=ENABLE,
                                 is_extended_id=False, is_fd=command.is_fd,
                                 bitrate_switch=command.bitrate_switch))

    def on_message_received(self, msg: can.Message) -> None:
        motor = self._motors.get((msg.channel, msg.arbitration_id))
        if motor is None or motor.command is None or len(msg.data) < 8:
            return
        try:
            feedback = unpack_feedback(bytes(msg.data[:8]), motor.ranges)
        except ValueError:
            return
        motor.state = feedback.state
        if motor.held is None:
            motor.held = feedback.position
        # one slice assignment: the paced loop never sends half of it
        motor.command.data[:] = pack_command_values(motor.held, 0.0, motor.kp, motor.kd, 0.0,
                                                    motor.ranges)

    def enabled(self) -> int:
        """How many motors last reported ENABLED."""
        return sum(motor.state is State.ENABLED for motor in self._motors.values())
