"""A whole hil stack in one process: simulator, CAN master and control node, on buses of
this process (python-can ``hil-virtual`` by default) with the control node's Zenoh session
on loopback. For scripts, the bench and the tests; ``hil up`` runs the same parts as
separate processes.

Example (move the ur3's elbow, read where it went)::

    from hil.bus_config import load_bus_config
    from hil.controllers import TrajectoryGoal, TrajectoryPoint
    from hil.messaging.zenoh_api import TrajectoryActionClient
    from hil.stack import running_stack

    config = load_bus_config("ur3")
    with running_stack(config) as stack:
        client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        goal = TrajectoryGoal(("joint3",), (TrajectoryPoint(1.0, (0.5,), (0.0,)),))
        result = client.wait_result(client.send_goal(goal), timeout=10)
        print(result.error_code, stack.sim.plant.joint_positions()[2])
        client.close()
"""

from __future__ import annotations

import gc
import threading
import time
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import can

from hil.bus_config import SystemConfig
from hil.can.faults import FaultyBus
from hil.control_node import ControlNode, FaceFactory
from hil.controllers.config import controllers_for
from hil.hardware import LOCK_STEP_REPLY_TIMEOUT, CanHardwareInterface
from hil.simulator import Simulator
from hil.zenoh_session import ZenohSettings, close, free_loopback_port, session
from hil.realtime.timing import REAL_TIME, Timing

#: a real-time bring-up on a loaded machine can miss answers and fault: it is tried again
START_ATTEMPTS = 3


class StackDidNotStart(RuntimeError):
    """No attempt of :func:`running_stack` brought its controller to cycling; the message
    gives every attempt's reason."""


#: the stacks' default bus: python-can's virtual bus, frames handed over in the sender's
#: thread
IN_PROCESS = "hil-virtual"


class Stack:
    """Simulator, CAN master and control node of one bus config, started in threads of this
    process. The sim's buses are wrapped in FaultyBus where faults are to be injected
    (``injectable``; only then: ``hil sim`` has no such layer)."""

    def __init__(self, config: SystemConfig, timing: Timing = REAL_TIME,
                 interface: str = IN_PROCESS, channels: dict[str, str] | None = None,
                 injectable: bool = False, faces: Sequence[FaceFactory] = ()):
        """``faces``: the control node's faces beyond hil's own keys (see ControlNode)."""
        tag = uuid.uuid4().hex[:8]
        self.config = config
        #: bus name -> channel
        self.channels = channels or {b.name: f"hil-stack-{tag}-{b.name}" for b in config.buses}
        self._opened = [can.Bus(interface=interface, channel=self.channels[b.name])
                        for b in config.buses for _ in range(2)]
        #: bus name -> the sim's end of it
        self.sim_buses = {b.name: FaultyBus(self._opened[2 * i], []) if injectable
                          else self._opened[2 * i] for i, b in enumerate(config.buses)}
        try:
            self.sim = Simulator(config, self.sim_buses, timing)
        except BaseException:       # a config the plant or a sensor refuses: no bus left open
            for bus in self._opened:
                bus.shutdown()
            raise
        self.sim.start()
        self._sim_thread = threading.Thread(target=self.sim.run, daemon=True)
        self._sim_thread.start()
        self.zenoh_settings = ZenohSettings(listen=(f"tcp/127.0.0.1:{free_loopback_port()}",))
        #: the control node's Zenoh session (goals, joint states, diagnostics)
        self.zenoh = session(self.zenoh_settings)
        hardware = CanHardwareInterface(
            config, {b.name: self._opened[2 * i + 1] for i, b in enumerate(config.buses)},
            reply_timeout=LOCK_STEP_REPLY_TIMEOUT if timing.lock_step else None)
        self.node = ControlNode(hardware, self.zenoh, config.cycle_hz, timing,
                                controllers=controllers_for(config), faces=faces)
        #: why the control node's bring-up failed, if it did
        self.error: Exception | None = None
        self._node_thread = threading.Thread(target=self._run_node, daemon=True)
        self._node_thread.start()

    def _run_node(self) -> None:
        try:
            self.node.run()
        except Exception as exc:         # a failed bring-up: reported by running()
            self.error = exc

    def running(self, timeout: float = 30.0) -> bool:
        """Wait until the controller runs its cycles (False if its bring-up failed)."""
        deadline = time.monotonic() + timeout
        while not self.node.cycling:
            if self.error is not None or time.monotonic() > deadline:
                return False
            time.sleep(0.01)
        return True

    def alive(self) -> bool:
        """Whether the simulator's and the control node's threads still run."""
        return self._sim_thread.is_alive() and self._node_thread.is_alive()

    def close(self) -> None:
        """Stop the control node (drives disabled) and the simulator; close every bus and
        the Zenoh session."""
        self.node.stop()
        self._node_thread.join(10)
        self.sim.stop()
        self._sim_thread.join(5)
        self.sim.close()
        for bus in list(self.sim_buses.values()) + self._opened[1::2]:
            bus.shutdown()
        close(self.zenoh_settings)      # its listener and threads would outlive the stack


@contextmanager
def running_stack(config: SystemConfig, timing: Timing = REAL_TIME, interface: str = IN_PROCESS,
                  channels: dict[str, str] | None = None, injectable: bool = False,
                  faces: Sequence[FaceFactory] = ()) -> Iterator[Stack]:
    """A :class:`Stack` whose controller cycles (tried START_ATTEMPTS times;
    :class:`StackDidNotStart` with every attempt's reason if none comes up), closed on exit."""
    failures = []
    for _ in range(START_ATTEMPTS):
        stack = Stack(config, timing, interface, channels, injectable, faces)
        if stack.running():
            break
        failures.append(str(stack.error or "no bring-up within 30 s"))
        stack.close()
    else:
        raise StackDidNotStart(f"the stack did not start in {START_ATTEMPTS} attempts: "
                           + " | ".join(failures))
    gc.collect()
    gc.freeze()        # start-up's objects out of the collector's way, as hil sim/control do
    try:
        yield stack
    finally:
        stack.close()
