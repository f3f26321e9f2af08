"""What a simulated CiA 402 drive does with an RPDO's values: the objects it maps, set in the
order a drive takes them (CiA 402: the controlword after the targets, but before them in
interpolated position mode), through the state machine, the objects and the core."""

from __future__ import annotations

from hil.drives.core import DriveCore
from hil.protocols.cia402.objects import DriveObjects
from hil.protocols.cia402.pdo import Rpdo
from hil.protocols.cia402.state import INTERPOLATED_POSITION, Cia402StateMachine


class RpdoSet:
    """The RPDOs of one drive as mapped at its last PDO configuration (by number), and what
    applying them writes to. The drive makes a new one at each configuration."""

    def __init__(self, rpdos: dict[int, Rpdo], objects: DriveObjects,
                 machine: Cia402StateMachine, core: DriveCore, rated_torque: float):
        self.rpdos = rpdos
        self._objects, self._machine, self._core = objects, machine, core
        self._rated_torque = rated_torque

    def apply(self, number: int, data: bytes) -> None:
        """RPDO ``number``'s ``data`` applied (caller holds the lock)."""
        rpdo = self.rpdos[number]
        pdo = rpdo.pdo
        pdo.data = data         # canopen's variables read it where no layout unpacks it
        layout = rpdo.layout
        values = (layout.codec.unpack(data) if layout is not None
                  else [variable.raw for variable in pdo.map])
        at = rpdo.at            # each mapped object's place in values (no dict made a frame)
        objects, machine = self._objects, self._machine
        if rpdo.mode:
            objects.set_mode(values[at[0x6060]])
        for index in rpdo.profile:
            objects.set_profile_parameter(index, values[at[index]])
        # the controlword after the targets (profile position's new set-point takes the
        # target of its own PDO), but in ip mode before them: bit 4 gates its own PDO's record
        interpolated = machine.mode_code == INTERPOLATED_POSITION
        if rpdo.controlword and interpolated:
            machine.controlword(values[at[0x6040]])
        for index in rpdo.targets:      # objects.set_target_position's, a call less a frame
            machine.take_target_position(index, values[at[index]] / objects.counts_per_rad)
        if rpdo.torque:
            objects.set_target_torque(values[at[0x6071]])
        if rpdo.offsets:
            per_rad = objects.velocity_per_rad
            self._core.new_setpoint(
                velocity=values[at[0x60FF]] / per_rad if 0x60FF in at else None,
                velocity_ff=values[at[0x60B1]] / per_rad if 0x60B1 in at else None,
                torque_ff=values[at[0x60B2]] * self._rated_torque / 1000 if 0x60B2 in at
                else None)
        if rpdo.controlword and not interpolated:
            machine.controlword(values[at[0x6040]])
