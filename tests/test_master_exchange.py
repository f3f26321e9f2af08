"""The master's cycle on its buses (hil.hardware.exchange): a bus' frames of a cycle, then its
protocols' cycle-end frames once (CANopen: the SYNC after the RPDOs it makes the drives act on,
CiA 301 7.2.5), however many of its drives ask for them; none on a bus whose protocols have
none."""

from __future__ import annotations

import uuid

import can

from conftest import ROOT, UR3_VIRTUAL

from hil.bus_config import SystemConfig, load_bus_config
from hil.hardware.exchange import CycleExchange
from hil.protocols import protocol

PIGOT_MIXED = ROOT / "bus_config" / "pigot_mixed.yaml"


def _one_cycle(config: SystemConfig) -> dict[str, list[can.Message]]:
    """What each bus carries of one cycle of a master holding its axes (a python-can
    ``virtual`` bus listening beside the master's)."""
    tag = uuid.uuid4().hex[:8]
    channels = {bus.name: f"hil-exchange-{tag}-{bus.name}" for bus in config.buses}
    master = {name: can.Bus(interface="virtual", channel=channel)
              for name, channel in channels.items()}
    heard = {name: can.Bus(interface="virtual", channel=channel)
             for name, channel in channels.items()}
    exchange = CycleExchange(config, master, reply_timeout=0.01)
    try:
        exchange.open()
        for bus in heard.values():          # what opening sent: not the cycle's
            _drained(bus)
        still = [0.0] * len(exchange.axes)
        exchange.send(still, still, still, stopping=False, holding=True)
        return {name: _drained(bus) for name, bus in heard.items()}
    finally:
        for router in exchange.routers.values():
            router.stop()
        for bus in [*master.values(), *heard.values()]:
            bus.shutdown()


def _drained(bus: can.BusABC) -> list[can.Message]:
    """The frames waiting in ``bus`` (python-can's virtual bus queues them as they are
    sent)."""
    frames = []
    while (message := bus.recv(0)) is not None:
        frames.append(message)
    return frames


def _is_cycle_end(message: can.Message, cycle_end) -> bool:
    return any((message.arbitration_id, bytes(message.data), message.is_extended_id)
               == (frame.identifier, frame.data, frame.extended) for frame in cycle_end)


def test_a_canopen_bus_gets_one_sync_after_its_cycles_frames_whatever_its_drive_count():
    config = load_bus_config(UR3_VIRTUAL)
    sync = protocol("cia402").cycle_end_frames
    arm = _one_cycle(config)["arm"]
    assert len(arm) > len(config.buses[0].drives)        # every drive's frames, then SYNC
    assert [m for m in arm if _is_cycle_end(m, sync)] == [arm[-1]]


def test_buses_whose_protocols_end_no_cycle_get_no_cycle_end_frame():
    config = load_bus_config(PIGOT_MIXED)
    sync = protocol("cia402").cycle_end_frames
    for name, frames in _one_cycle(config).items():
        assert frames, name                                # the axes' own frames went out
        assert not [m for m in frames if _is_cycle_end(m, sync)], name
