"""The frames of one control cycle, per bus, as the bare baselines exchange them."""

from __future__ import annotations

import can

from hil.bus_config import SystemConfig


def cyclic_frames(config: SystemConfig) -> list[tuple[str, list[can.Message], list[can.Message]]]:
    """Per bus: (name, the frames the master sends each cycle, the last of them the one
    the drives answer, and the answers). SYNC where the protocol uses it."""
    exchanges = []
    for bus in config.buses:
        out, answers = [], []
        for drive in bus.drives:
            cyclic = [f for f in bus.frames(drive) if f[2] == bus.cycle_hz]
            master_ids = {cyclic[0][0]}     # the master's frame is the exchange's first
            for can_id, size, _ in cyclic:
                frame = can.Message(arbitration_id=can_id, data=bytes(size),
                                    is_extended_id=False)
                (out if can_id in master_ids else answers).append(frame)
        if bus.uses_sync:
            out.append(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        exchanges.append((bus.name, out, answers))
    return exchanges
