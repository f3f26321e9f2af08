"""2b-t/myactuator_rmd's Python bindings (C++17 over SocketCAN) drive hil's RMD motor through
their README's sequence. They are not on PyPI (built from source with CMake and pybind11):
without them this module is skipped whole at collection, so the SocketCAN suite inside
User-Mode Linux (test_socketcan_in_uml.py, where no SocketCAN test may be skipped) does not
collect it. The motor and its config are tests/test_myactuator.py's."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from conftest import RealTimeMaster, socketcan_missing
from hil.drives import Power
from test_myactuator import one_axis

pytest.importorskip("myactuator_rmd_py", reason=(
    "2b-t/myactuator_rmd's Python bindings are not installed: they are not on PyPI; build "
    "them from github.com/2b-t/myactuator_rmd (CMake, pybind11) to run this"))

#: 2b-t/myactuator_rmd's README sequence, run in a process of its own: its calls hold the
#: GIL while they wait for the answer (pybind11 releases it only where told), so in the
#: bench's process the simulated motor could not answer before the SDK's 1 s timeout
SDK_SEQUENCE = """
import json, time
import myactuator_rmd_py as rmd
driver = rmd.CanDriver("vcan0")
actuator = rmd.ActuatorInterface(driver, 1)
version = actuator.getVersionDate()
feedback = actuator.sendPositionAbsoluteSetpoint(90.0, 200.0)
time.sleep(1.5)
angle = actuator.getMultiTurnAngle()
status = actuator.getMotorStatus2()
actuator.shutdownMotor()
print(json.dumps([version, feedback.temperature, angle, status.shaft_angle]))
"""


@pytest.mark.socketcan
def test_myactuator_rmd_sdk_drives_the_motor_through_its_readme_sequence_over_socketcan(
        tmp_path):
    """2b-t/myactuator_rmd's Python bindings (C++17 over SocketCAN; not on PyPI, built from
    source with CMake and pybind11: the test runs where it is installed): its README's
    CanDriver, ActuatorInterface(driver, 1), getVersionDate, sendPositionAbsoluteSetpoint
    (0xA4, degrees and dps), shutdownMotor (0x80), with getMultiTurnAngle (0x92) and
    getMotorStatus2 (0x9C) to look."""
    missing = socketcan_missing()
    if missing:
        pytest.skip(missing)
    master = RealTimeMaster.of(one_axis(tmp_path), vcan="vcan0")
    try:
        done = subprocess.run([sys.executable, "-c", SDK_SEQUENCE], capture_output=True,
                              text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        version, temperature, angle, shaft_angle = json.loads(done.stdout)
        assert (version, temperature, shaft_angle) == (20220206, 25, 90)
        assert angle == pytest.approx(90.0, abs=0.5)
        assert master.joint() == pytest.approx(math.pi / 2, abs=0.01)
        assert master.drive.core.power is Power.DISABLED
    finally:
        master.close()
