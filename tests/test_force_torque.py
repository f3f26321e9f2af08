"""A six-axis force-torque sensor, ATI's Net F/T on CAN: its answers in the manual's layout,
read by a master written from the manual (ATI publishes no client library), the bias
command, the config's checks; on the pigot's wrist it weighs the cube the gripper lifts."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import can
import numpy as np
import pytest
import yaml
from conftest import RecordingRouter, sensor_messages

from hil.bus_config import load_bus_config
from hil.can.faults import SensorFaultKind
from hil.can.frame import Frame
from hil.controllers import TrajectoryGoal, TrajectoryPoint
from hil.errors import ConfigError
from hil.messaging import cdr
from hil.messaging.zenoh_api import TrajectoryActionClient
from hil.protocols import ati_netft
from hil.realtime import LOCK_STEP
from hil.sensors.force_torque import SimulatedForceTorque
from hil.stack import IN_PROCESS, running_stack

ROOT = Path(__file__).resolve().parents[1]
BASE = 0x10
CUBE_WEIGHT = 0.05 * 9.81          # bus_config/pigot_pick.yaml's cube: 50 g


def _pick_config(folder: Path, **sensor) -> Path:
    """bus_config/pigot_pick.yaml with a Net F/T on the hand (arm_link_6, which carries the
    fingers) at base 0x10 of the wrist bus, written into ``folder``."""
    config = yaml.safe_load((ROOT / "bus_config" / "pigot_pick.yaml").read_text())
    config["robot"] = str((ROOT / "bus_config" / config["robot"]).resolve())
    config["sensors"] = [{"name": "wrist_ft", "product": "ati_netft", "link": "arm_link_6",
                          "bus": "wrist", "base_id": BASE, **sensor}]
    path = folder / "pigot_ft.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


class NetFtReader:
    """A Net F/T master as the manual (section 15) tells one to be written: a request byte
    to the base id, the answers' little-endian counts divided by counts per unit."""

    def __init__(self, bus: can.BusABC, base: int, counts_per_force: float = 1e6,
                 counts_per_torque: float = 1e6):
        self.bus, self.base = bus, base
        self.cpf, self.cpt = counts_per_force, counts_per_torque

    def command(self, code: int) -> None:
        # what came before (hil control polls the sensor too) answers earlier requests
        while self.bus.recv(0) is not None:
            pass
        self.bus.send(can.Message(arbitration_id=self.base, data=[code], is_extended_id=False))

    def long(self) -> tuple[np.ndarray, np.ndarray, int]:
        """(force N, torque N·m, sample number) of one long-data request."""
        self.command(0x01)
        frames = self._answers(range(self.base + 1, self.base + 5))
        pairs = [struct.unpack("<ii", frames[self.base + n]) for n in (1, 2, 3)]
        status, sample = struct.unpack("<iI", frames[self.base + 4])
        assert status == 0
        return (np.array([p[0] for p in pairs]) / self.cpf,
                np.array([p[1] for p in pairs]) / self.cpt, sample)

    def short(self) -> tuple[np.ndarray, np.ndarray]:
        """(force, torque) in 16-bit counts of one short-data request (table 15.2)."""
        self.command(0x02)
        frames = self._answers((self.base + 5, self.base + 6))
        fx, tx, fy, ty = struct.unpack("<4h", frames[self.base + 5])
        fz, tz, status, _ = struct.unpack("<3hH", frames[self.base + 6])
        assert status == 0
        return np.array([fx, fy, fz]), np.array([tx, ty, tz])

    def _answers(self, identifiers) -> dict[int, bytes]:
        wanted, found = set(identifiers), {}
        deadline = time.monotonic() + 10
        while wanted - set(found) and time.monotonic() < deadline:
            message = self.bus.recv(0.5)
            if message is not None and message.arbitration_id in wanted:
                found[message.arbitration_id] = bytes(message.data)
        assert set(found) == wanted, f"answers {sorted(found)} of {sorted(wanted)}"
        return found

    def mean_force(self, count: int = 20) -> np.ndarray:
        return np.mean([self.long()[0] for _ in range(count)], axis=0)


def test_the_answers_are_the_manuals_layout():
    frames = ati_netft.short_answer(BASE, [1, -2, 3], [4, -5, 6], 0, 70000)
    assert [f.identifier for f in frames] == [BASE + 5, BASE + 6]
    assert struct.unpack("<4h", frames[0].data) == (1, 4, -2, -5)     # Fx Tx Fy Ty
    assert struct.unpack("<3hH", frames[1].data) == (3, 6, 0, 70000 & 0xFFFF)
    frames = ati_netft.long_answer(BASE, [10, 20, 30], [-1, -2, -3], 0, 9)
    assert [struct.unpack("<ii", f.data) for f in frames[:3]] == [(10, -1), (20, -2), (30, -3)]
    assert ati_netft.counts([1e9, -1e9, 0.5e-6], 1e6, 32) == [2 ** 31 - 1, -2 ** 31, 0]


def _long_answers(sensor: SimulatedForceTorque, router: RecordingRouter, now: list[float],
                  at: float) -> list[tuple[int, ...]] | None:
    """The long-data answer (Fx Tx ... status sample) a request at plant time ``at`` gets;
    None if none."""
    now[0] = at
    sent = len(router.sent)
    router.handlers[BASE](Frame(BASE, bytes((ati_netft.LONG,))))
    frames = router.sent[sent:]
    return [struct.unpack("<ii", f.data) for f in frames] if frames else None


@pytest.mark.parametrize("kind", list(SensorFaultKind))
def test_a_faulted_net_ft_answers_nothing_the_same_or_one_full_scale_answer(tmp_path, kind):
    config = load_bus_config(_pick_config(tmp_path)).force_torques[0]
    load = [np.array([1.0, 2.0, 3.0]), np.zeros(3)]
    now = [0.0]
    sensor = SimulatedForceTorque(config, lambda: tuple(load), lambda: now[0])
    router = RecordingRouter()
    sensor.attach(router)
    sensor.inject(kind, 1.0)
    assert _long_answers(sensor, router, now, 0.5) is not None
    load[0] = np.array([4.0, 5.0, 6.0])
    first, second = (_long_answers(sensor, router, now, t) for t in (1.2, 1.3))
    if kind is SensorFaultKind.SILENCE:
        assert first is None and second is None
    elif kind is SensorFaultKind.FREEZE:                  # the sample number stands still too
        assert first == second and first[0][0] == pytest.approx(4e6, abs=1e4)
    else:
        assert first[0][0] == 2 ** 31 - 1 and second[0][0] == pytest.approx(4e6, abs=1e4)


class Pick:
    """The pigot of :func:`_pick_config` in lock-step, a Net F/T master on its wrist bus and a
    trajectory client: goals for its arm_rot_3 and finger_pri_1 from where they start."""

    def __init__(self, stack, config):
        self.bus = can.Bus(interface=IN_PROCESS, channel=stack.channels["wrist"])
        self.reader = NetFtReader(self.bus, BASE)
        self.client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        self.plant = plant = stack.sim.plant
        arm_rot_3 = float(plant.joint_positions()[plant.joint_names.index("arm_rot_3")])
        limits = config.robot.joint("arm_rot_3").limits
        self.arm = min(max(arm_rot_3, limits.lower), limits.upper)
        self.open = float(plant.joint_positions()[plant.joint_names.index("finger_pri_1")])

    def hold(self, *points: tuple[float, float, float]) -> None:
        """(time, arm_rot_3, finger_pri_1) points, at rest each, the goal succeeded."""
        goal = TrajectoryGoal(("arm_rot_3", "finger_pri_1"), tuple(
            TrajectoryPoint(at, (arm, fingers), (0.0, 0.0)) for at, arm, fingers in points))
        result = self.client.wait_result(self.client.send_goal(goal), 120)
        assert result.error_code == 0, result

    def raise_open(self) -> None:
        """The arm raised with the fingers open, at rest: the hand and its fingers alone (at
        the start pose the sagged hand rests on the cube: the sensor reads that push, 50 N,
        as a real one would)."""
        self.hold((2.0, self.arm - 0.2, self.open), (3.0, self.arm - 0.2, self.open))

    def close(self) -> None:
        self.client.close()
        self.bus.shutdown()


def test_the_wrist_sensor_weighs_the_cube_the_gripper_lifts(tmp_path):
    config = load_bus_config(_pick_config(tmp_path))
    with running_stack(config, LOCK_STEP) as stack:
        pick = Pick(stack, config)
        try:
            pick.raise_open()
            empty = pick.reader.mean_force()
            # back down, then as tests/test_contacts.py's pick: fingers on the cube, the arm
            # raised, held
            arm = pick.arm
            pick.hold((2.0, arm, pick.open), (3.0, arm, 0.026), (3.5, arm, 0.026),
                      (5.5, arm - 0.2, 0.026), (7.0, arm - 0.2, 0.026))
            lifted = pick.plant.object_pose("cube")[0][2]
            holding = pick.reader.mean_force()
        finally:
            pick.close()
    assert lifted > 0.8                                        # off its post (0.76 m)
    # the hand and its fingers weigh the same either way: the difference is the cube
    weighed = np.linalg.norm(holding) - np.linalg.norm(empty)
    assert weighed == pytest.approx(CUBE_WEIGHT, rel=0.05), (empty, holding)


def test_bias_zeroes_the_reading_and_short_data_counts_in_its_divisors(tmp_path):
    # the hand at rest and free: right after the bring-up it rests on the cube and settles
    # by tens of mN between two readings (a short reading against a long one: flaky)
    config = load_bus_config(_pick_config(tmp_path))
    with running_stack(config, LOCK_STEP) as stack:
        pick = Pick(stack, config)
        reader = pick.reader
        try:
            pick.raise_open()
            loaded = reader.mean_force(5)
            force, _ = reader.short()
            reader.command(0x04)
            biased = reader.mean_force(5)
            _, _, first = reader.long()
            time.sleep(0.2)
            _, _, later = reader.long()
        finally:
            pick.close()
    assert np.linalg.norm(loaded) > 0.9                    # the hand's weight (0.97 N)
    assert force == pytest.approx(loaded * 1000, abs=50)   # 1 mN a count (the default)
    assert np.linalg.norm(biased) < 0.05 and later > first      # zeroed; its counter runs


@pytest.mark.parametrize("sensor, message", [
    ({"base_id": 0x7FD}, "'base_id' is 0 to 0x7F9"),
    ({"bus": "nowhere"}, "the config has no bus 'nowhere'"),
    ({"rate_hz": 100}, "'rate_hz' is not for a ati_netft sensor"),
    ({"short_divisors": [0, 1]}, "'short_divisors' is [forces, torques]"),
    ({"base_id": 0x184 - 1}, "CAN id 0x184 is used by sensor 'wrist_ft' long data 1 and by "
                             "node 4"),
])
def test_a_bad_force_torque_entry_is_refused_naming_it_and_its_line(tmp_path, sensor, message):
    with pytest.raises(ConfigError) as refused:
        load_bus_config(_pick_config(tmp_path, **sensor))
    assert message in str(refused.value) and "pigot_ft.yaml:" in str(refused.value)


def test_the_controller_polls_the_sensor_and_publishes_geometry_msgs_wrench(tmp_path):
    """hil control is the Net F/T's master: long data requested at poll_hz, every answer
    published as geometry_msgs/WrenchStamped on hil/<robot>/sensors/<name>/wrench."""
    config = load_bus_config(_pick_config(tmp_path, poll_hz=50))
    messages = sensor_messages(config, "wrist_ft", "wrench", cdr.WRENCH_STAMPED, 5)
    last = messages[-1]
    assert last.header.frame_id == "arm_link_6"
    force = [last.wrench.force.x, last.wrench.force.y, last.wrench.force.z]
    assert np.linalg.norm(force) > 0.9          # the hand's weight at least (0.97 N)
    stamps = [cdr.seconds_of(m.header.stamp) for m in messages]
    assert stamps == sorted(stamps)


def test_the_poll_rate_counts_in_the_bus_load_and_may_not_pass_its_cycle(tmp_path):
    bare = load_bus_config(ROOT / "bus_config" / "pigot_pick.yaml").buses[1].load()
    polled = load_bus_config(_pick_config(tmp_path, poll_hz=100)).buses[1].load()
    assert polled.frames_per_second - bare.frames_per_second == pytest.approx(500)
    with pytest.raises(ConfigError, match="'poll_hz' 1000 is over its bus' cycle rate"):
        load_bus_config(_pick_config(tmp_path, poll_hz=1000))
