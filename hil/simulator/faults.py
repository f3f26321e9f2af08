"""Fault injection into a simulated bench: a drive found by its config entry or by the node
id it has now, and the faults ``hil sim --fault`` injects."""

from __future__ import annotations

from contextlib import AbstractContextManager

from hil.bus_config import DriveConfig, SystemConfig
from hil.can.faults import DriveFaultKind
from hil.drives import DriveProfile, Fault
from hil.errors import HilError
from hil.simulator.build import SimulatedBus
from hil.simulator.cycles import CycleBook


class FaultInjection:
    """The drives of a config by entry, and faults injected into them (under ``lock``)."""

    def __init__(self, config: SystemConfig, buses: list[SimulatedBus],
                 lock: AbstractContextManager, cycles: CycleBook):
        self._path = config.path
        self._lock = lock
        self._cycles = cycles
        #: (bus name, config entry, its drive) in the config's order: a drive by its entry
        self._entries: list[tuple[str, DriveConfig, DriveProfile]] = [
            (simulated.config.name, entry, drive) for simulated in buses
            for entry, drive in zip(simulated.config.drives, simulated.drives, strict=True)]

    def configured(self, drive: DriveConfig) -> DriveProfile:
        """The drive of an entry of the config, whatever node id an LSS master has given it
        since (CiA 305 configure node id)."""
        for _, entry, profile in self._entries:
            if entry == drive:
                return profile
        raise KeyError(f"no drive {drive.label} in {self._path}")

    def drive(self, bus: str, node_id: int) -> DriveProfile:
        """The drive that has ``node_id`` on ``bus`` now (LSS may have changed the config's);
        HilError where none has it, or two do (an LSS master gave a taken id: either would
        be a guess)."""
        with self._lock:
            on_bus = [(entry, profile) for name, entry, profile in self._entries if name == bus]
            found = [(entry, profile) for entry, profile in on_bus if profile.node_id == node_id]
        if len(found) == 1:
            return found[0][1]
        if not found:
            there = sorted({profile.node_id for _, profile in on_bus})
            raise HilError.single(f"no drive has node id {node_id} on bus '{bus}' now",
                                  self._path, hint="node ids there now: " + (
                                      ", ".join(map(str, there)) or "none (no such bus)"))
        joints = " and of ".join(", ".join(entry.joints) for entry, _ in found)
        raise HilError.single(f"node id {node_id} on bus '{bus}' is the drive of {joints} (an "
                              "LSS master gave it to each)", self._path,
                              hint="name the drive by its joint (DrivesBench.state/fault(JOINT))"
                                   ", or give each its own node id")

    def inject(self, kind: DriveFaultKind, drive: DriveProfile) -> None:
        """A drive fault (``hil sim --fault``'s kinds): ``silence``, it leaves its bus (its
        physics runs on); ``restart``, as after a power cycle (it boots again, unconfigured);
        ``fault``, as on a following error (it reports it in its protocol)."""
        with self._lock:
            if kind is DriveFaultKind.SILENCE:
                drive.detach()
                self._cycles.leave(drive)
            elif kind is DriveFaultKind.RESTART:
                drive.restart()
            else:
                drive.core.raise_fault(Fault.FOLLOWING_ERROR)
                drive.after_update()
