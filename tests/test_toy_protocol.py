"""A device family from outside hil sends and answers 29-bit CAN FD frames of 64 bytes with the
bit-rate switch through hil's simulator and master (issue 66's acceptance).

The family is tests/fixtures/toy_protocol: a package and its ``.dist-info`` as pip leaves an
installed one, registered under the entry-point group ``hil.protocols``
(:mod:`hil.protocols`), with nothing of it inside hil. Its frames cross an in-process bus
(``hil-virtual``) and a Zenoh bus in lock-step; a python-can listener on the bus and a BLF
log (as ``hil replay`` reads) see them as ISO 11898-1:2015 says a CAN FD frame is: FDF (python-can's
``is_fd``), BRS (``bitrate_switch``), IDE (``is_extended_id``) and 64 data bytes.
"""

from __future__ import annotations

import threading
import uuid

import can
import numpy as np
import pytest

from conftest import TESTS, FrameRecorder, socketcan_missing
from hil.bus_config import load_bus_config, open_buses
from hil.can.frame import Frame
from hil.can.monitor import NumberedChannels
from hil.hardware import LOCK_STEP_REPLY_TIMEOUT, CanHardwareInterface
from hil.realtime import LOCK_STEP
from hil.simulator import Simulator
from hil.zenoh_session import ZenohSettings

ROBOT = TESTS / "fixtures" / "damiao_one_axis.urdf"
#: python-can's side of each bus for the listener: the plain ``virtual`` interface shares
#: hil-virtual's channels
LISTENER = {"hil-virtual": "virtual", "zenoh": "zenoh", "socketcan": "socketcan"}
#: a vcan, which takes CAN FD frames (its MTU 72), and one with the classical MTU 16
#: (tools/uml_run.py --vcan vcancc0+classic)
FD_VCAN, CLASSICAL_VCAN = "vcan0", "vcancc0"


def toy_config(folder, interface: str, channel: str):
    path = folder / "toy.yaml"
    path.write_text(f"""\
robot: {ROBOT}
transmissions:
  yaw: {{reduction: 1, rotor_inertia: 0.0018}}
defaults: {{protocol: toy}}
buses:
  - name: axis
    interface: {interface}
    channel: {channel}
    cycle_hz: 100
    fd: true
    drives:
      - {{node_id: 1, joint: yaw}}
""")
    return load_bus_config(path)


class ToyBus:
    """The toy config's bus with its ends in this process: the drive in a lock-step
    Simulator, hil's master (CanHardwareInterface), and a python-can listener logging every
    frame."""

    def __init__(self, config, interface: str, log):
        settings = ZenohSettings.meeting()
        self.sim_buses = open_buses(config, settings, lossless=True)
        self.master_buses = open_buses(config, settings, lossless=True)
        self.listener = can.Bus(interface=LISTENER[interface], channel=config.buses[0].channel,
                                fd=True)
        self.recorder = FrameRecorder()
        # the log as hil's monitor writes one: BLF numbers channels (hil.can.monitor)
        self.notifier = can.Notifier(self.listener, [
            self.recorder, NumberedChannels(can.Logger(log), {config.buses[0].channel: 1})])
        self.sim = Simulator(config, self.sim_buses, LOCK_STEP)
        self.sim.start()
        self.thread = threading.Thread(target=self.sim.run, daemon=True)
        self.thread.start()
        self.master = CanHardwareInterface(config, self.master_buses,
                                           reply_timeout=LOCK_STEP_REPLY_TIMEOUT)

    def close(self) -> None:
        self.master.stop()
        self.sim.stop()
        self.thread.join(5)
        self.sim.close()
        self.notifier.stop()               # and its log: the file closed
        for bus in [self.listener, *self.sim_buses.values(), *self.master_buses.values()]:
            bus.shutdown()


def fd_fields(msg: can.Message) -> tuple:
    return msg.is_fd, msg.bitrate_switch, msg.is_extended_id, msg.dlc, bytes(msg.data)


def as_logged(frame: Frame) -> tuple:
    """What a python-can listener says of a toy frame sent whole."""
    return True, True, True, 64, frame.data


@pytest.mark.parametrize("interface", [
    "hil-virtual", "zenoh", pytest.param("socketcan", marks=pytest.mark.socketcan)])
def test_a_family_from_an_entry_point_sends_and_answers_29_bit_64_byte_fd_frames(
        toy_installed, tmp_path, interface):
    from hil_toy_protocol import REPLY_BASE, values_of

    if interface == "socketcan" and (missing := socketcan_missing(FD_VCAN)):
        pytest.skip(missing)
    channel = FD_VCAN if interface == "socketcan" else f"toy/{uuid.uuid4().hex[:8]}"
    config = toy_config(tmp_path, interface, channel)
    log = tmp_path / "toy.blf"
    toy = ToyBus(config, interface, log)
    try:
        toy.master.start()                                     # heard, enabled
        drive, axis = toy.sim.drives[0], toy.master.axes[0]
        toy.master.write(np.array([0.1]), np.array([0.0]))
        toy.master.read()
        command, reply = drive.command, drive.reply
        # the axis' setpoint arrived bit for bit, and the drive's answer came back so
        target = toy.master.transmissions.joint_to_actuator_position(np.array([0.1]))[0]
        assert command.identifier == 1 and values_of(command) == (target, 0.0)
        assert reply.identifier == REPLY_BASE + 1
        assert values_of(reply) == (axis.feedback.position, axis.feedback.velocity)
        for frame in (command, reply):
            assert toy.recorder.wait_for_message(
                lambda msg, frame=frame: fd_fields(msg) == as_logged(frame), timeout=30)
    finally:
        toy.close()
    logged = [fd_fields(msg) for msg in can.LogReader(log)]
    assert as_logged(command) in logged and as_logged(reply) in logged
    assert all(fields[:4] == (True, True, True, 64) for fields in logged)


@pytest.mark.socketcan
def test_the_kernel_refuses_an_fd_frame_on_a_classical_vcan():
    """What a client meets that sends CAN FD to a classical bus over SocketCAN: an interface
    of the classical MTU (16) refuses the frame (EINVAL, python-can's CanOperationError),
    one of CAN FD's (72) carries it (Linux's Documentation/networking/can.rst)."""
    if missing := socketcan_missing(CLASSICAL_VCAN, FD_VCAN):
        pytest.skip(missing)
    fd_frame = can.Message(arbitration_id=0x1ABCDE, data=bytes(64), is_extended_id=True,
                           is_fd=True, bitrate_switch=True)
    with can.Bus(interface="socketcan", channel=CLASSICAL_VCAN, fd=True) as classical, \
            can.Bus(interface="socketcan", channel=FD_VCAN, fd=True) as fd_bus, \
            can.Bus(interface="socketcan", channel=FD_VCAN, fd=True) as listener:
        with pytest.raises(can.CanOperationError):
            classical.send(fd_frame)
        fd_bus.send(fd_frame)
        heard = listener.recv(5)
    assert heard is not None and (heard.is_fd, heard.bitrate_switch, heard.dlc) == (
        True, True, 64)
