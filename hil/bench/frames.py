"""The frames of one control cycle, per bus, as the bare baselines exchange them."""

from __future__ import annotations

import can

from hil.bus_config import SystemConfig
from hil.can.frame import Frame, FrameSpec
from hil.can.messages import message_of


def cyclic_frames(config: SystemConfig) -> list[tuple[str, list[can.Message], list[can.Message]]]:
    """Per bus: (name, the frames the master sends each cycle, the last of them the one
    the drives answer, and the answers). The bus' cycle-end frames (CANopen's SYNC) last,
    where its protocols send them."""
    exchanges = []
    for bus in config.buses:
        out, answers = [], []
        for drive in bus.drives:
            cyclic = [spec for spec in bus.frames(drive) if spec.rate == bus.cycle_hz]
            master = cyclic[0]          # the master's frame is the exchange's first
            for spec in cyclic:
                (out if _same_id(spec, master) else answers).append(_zeros(spec))
        out += [message_of(frame) for frame in bus.cycle_end_frames]
        exchanges.append((bus.name, out, answers))
    return exchanges


def _same_id(spec: FrameSpec, other: FrameSpec) -> bool:
    return spec.identifier == other.identifier and spec.extended == other.extended


def _zeros(spec: FrameSpec) -> can.Message:
    """A frame of ``spec`` carrying zeros."""
    return message_of(Frame(spec.identifier, bytes(spec.length), spec.extended, spec.fd,
                            spec.bitrate_switch))
