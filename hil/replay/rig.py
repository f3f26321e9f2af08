"""A replay's rig: a fresh simulator of a bus config, and per bus a feeder that sends it the
log's master frames and a collector of the drives' answers (in the feeding thread).

Each bus is an in-process ``hil-virtual`` channel of its own (a random tag: replays side by
side never share one), the simulator on one end and the feeder on the other.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence

import can

from hil.bus_config import DriveConfig, SystemConfig
from hil.can.delivery import FrameListener
from hil.can.frame import Frame
from hil.can.messages import frame_of
from hil.drives.profile import DriveProfile
from hil.simulator import Simulator
from hil.realtime.timing import LOCK_STEP, REAL_TIME


class BusAnswers(FrameListener):
    """The replayed drives' frames of one bus, as they come (in the feeding thread)."""

    def __init__(self):
        self.frames: list[Frame] = []

    def on_frames(self, frames: Sequence[Frame]) -> None:
        self.frames.extend(frames)

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append(frame_of(msg))


class Rig:
    """A fresh simulator of ``config`` on the clock a replay's ``clock`` names, a feeder and
    an answer collector per bus, and its drives by bus index and node id."""

    def __init__(self, config: SystemConfig, clock: str):
        tag = uuid.uuid4().hex[:8]
        self._buses: list[can.BusABC] = []
        sim_buses = {}
        self.feeders: list[can.BusABC] = []
        #: per bus: the drives' answers since they were last taken
        self.answers: list[BusAnswers] = []
        for bus in config.buses:
            channel = f"hil-replay-{tag}-{bus.name}"
            sim_buses[bus.name] = can.Bus(interface="hil-virtual", channel=channel)
            feeder = can.Bus(interface="hil-virtual", channel=channel)
            answers = BusAnswers()
            feeder.deliver_to([answers])
            self.feeders.append(feeder)
            self.answers.append(answers)
            self._buses += [sim_buses[bus.name], feeder]
        self.sim = Simulator(config, sim_buses, LOCK_STEP if clock == "cycles" else REAL_TIME)
        #: (bus index, node id) -> (its config, its simulated drive)
        self.drives: dict[tuple[int, int], tuple[DriveConfig, DriveProfile]] = {}
        for index, (bus, simulated) in enumerate(zip(config.buses, self.sim.buses)):
            for drive_config, drive in zip(bus.drives, simulated.drives):
                self.drives[index, drive_config.node_id] = (drive_config, drive)
        #: per bus: its (node id, simulated drive)
        self.on_bus = [[(node, drive) for (b, node), (_, drive) in self.drives.items()
                        if b == index] for index in range(len(config.buses))]
        #: the plant's actuators, and (bus index, node id) -> its drive's actuator's index
        self.actuators = tuple(self.sim.plant.actuator_names)
        self.actuator = {key: self.actuators.index(c.actuator)
                         for key, (c, _) in self.drives.items()}

    def start(self) -> None:
        """The simulator started, the drives' answers so far (boot-ups before the master)
        dropped: not compared."""
        self.sim.start()
        for answers in self.answers:
            answers.frames.clear()

    def close(self) -> None:
        self.sim.close()
        for bus in self._buses:
            bus.shutdown()
