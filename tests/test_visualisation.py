"""Recording a run to rerun: control samples on the wire, the recorder, the bus-load meter."""

from __future__ import annotations

import collections
import os
import signal
import threading
import time
import math
import xml.etree.ElementTree as ET

import can
import numpy as np
import pytest
import rerun as rr
import rerun.chunk

from hil.can.frame import FrameSpec
from hil.can.frames import BitRates, bus_load
from hil.can.monitor import BusLoadMeter, BusMonitor, MeasuredLoad
from hil.controllers.demo import demo_goal
from hil.description.source import read_robot_source
from hil.hardware import JointFeedback
from hil.messaging import cdr
from hil.messaging.diagnostics import DiagnosticStatus
from hil.messaging.samples import ControlSampleBuffer, ControlSamples
from hil.visualisation import BenchParts, RunRecorder, SimTimeMap
from hil.visualisation.bus_time import BusTimeLoads
from hil.visualisation.node import VizNode
from conftest import PIGOT_XACRO, ROOT, UR3_XACRO, read_rrd

PIGOT_CONFIG = ROOT / "bus_config" / "pigot.yaml"


def feedback(positions, actuators: int, state: str = "OPERATION ENABLED") -> JointFeedback:
    positions = np.asarray(positions, dtype=float)
    return JointFeedback(positions, positions * 2, positions * 3, np.full(actuators, 0.5),
                         (state,) * actuators)


def make_batches(joints, actuators, count: int, size: int, states=None):
    """`count` batches of `size` consecutive cycles; position of joint i = cycle + i/10."""
    buffer = ControlSampleBuffer(joints, actuators, 0.002, size)
    batches, cycle = [], 0
    for _ in range(count):
        for _ in range(size):
            cycle += 1
            positions = cycle + np.arange(len(joints)) / 10
            state = states(cycle) if states else "OPERATION ENABLED"
            buffer.add(cycle, cycle * 0.002, positions + 0.01, np.zeros(len(joints)),
                       feedback(positions, len(actuators), state))
        batches.append(buffer.take())
    return batches


def test_control_samples_survive_encoding_exactly():
    batch = make_batches(("a", "b"), ("m1", "m2"), 1, 7,
                         states=lambda c: "FAULT" if c > 4 else "OPERATION ENABLED")[0]
    decoded = ControlSamples.decode(batch.encode())
    assert decoded.first_cycle == 1 and len(decoded) == 7
    assert decoded.joint_names == ("a", "b") and decoded.actuator_names == ("m1", "m2")
    for name in ("wall_time", "control_time", "reference", "position", "velocity", "effort",
                 "motor_torque", "drive_state"):
        np.testing.assert_array_equal(getattr(decoded, name), getattr(batch, name))
    names = [decoded.state_names[c] for c in decoded.drive_state[:, 0]]
    assert names == ["OPERATION ENABLED"] * 4 + ["FAULT"] * 3


def test_malformed_control_samples_are_refused_with_the_field_named():
    batch = make_batches(("a", "b"), ("m1",), 1, 3)[0]
    with pytest.raises(ValueError, match="malformed"):
        ControlSamples.decode(batch.encode()[:-9])
    with pytest.raises(ValueError, match="malformed"):
        ControlSamples.decode(b"\x00\x01\x00\x00garbage")
    short = ControlSamples(**{**batch.__dict__, "position": batch.position[:2]})
    with pytest.raises(ValueError, match="'position' has 4 values, 3 cycles x 2 expected"):
        ControlSamples.decode(short.encode())


def test_diagnostics_survive_encoding_and_malformed_ones_are_refused_naming_what():
    fault = DiagnosticStatus("ERROR", "drive node 2 (joint2) on bus 'arm' is in FAULT",
                             1.7e9 + 0.25, 12.5, hardware_id="ur3")
    assert DiagnosticStatus.decode(fault.encode()) == [fault]
    foreign = DiagnosticStatus("WARN", "from a ROS node", 1.7e9, None, name="other")
    assert DiagnosticStatus.decode(foreign.encode()) == [foreign]      # no controller clock
    with pytest.raises(ValueError, match="malformed diagnostic_msgs"):
        DiagnosticStatus.decode(fault.encode()[:-5])

    def status(level: int, control_time: str):
        return cdr.msg(cdr.DIAGNOSTIC_STATUS, level=level, name="hil control", message="m",
                       hardware_id="", values=[cdr.msg("diagnostic_msgs/msg/KeyValue",
                                                       key="control_time", value=control_time)])

    def array(*statuses):
        return cdr.encode(cdr.msg(cdr.DIAGNOSTIC_ARRAY, header=cdr.header(0.0), status=list(statuses)))

    with pytest.raises(ValueError, match="level 7 of 'hil control'"):
        DiagnosticStatus.decode(array(status(7, "1.0")))
    for bad in ("soon", "nan"):
        with pytest.raises(ValueError, match=f"control_time '{bad}' of 'hil control' is not"):
            DiagnosticStatus.decode(array(status(2, "1.0"), status(2, bad)))


def test_sample_buffer_reuses_its_arrays_and_starts_each_batch_at_its_first_cycle():
    buffer = ControlSampleBuffer(("a",), ("m",), 0.001, 3)
    for cycle in (10, 11):
        buffer.add(cycle, 0.0, np.ones(1), np.zeros(1), feedback([1.0], 1))
    first = buffer.take()
    assert (first.first_cycle, len(first), first.next_cycle) == (10, 2, 12)
    assert buffer.take() is None
    for cycle in (12, 13, 14, 15):          # the fourth does not fit: ignored, never wrapped
        buffer.add(cycle, 0.0, np.ones(1), np.zeros(1), feedback([2.0], 1))
    assert buffer.full
    second = buffer.take()
    assert (second.first_cycle, len(second)) == (12, 3)
    assert first.position[0, 0] == 1.0      # the first batch was copied out, not aliased


def test_sim_time_map_interpolates_between_clock_pairs_and_extrapolates_at_their_rate():
    sim_time = SimTimeMap()
    assert sim_time(np.array([1.0])) is None
    sim_time.add(100.0, 0.0)
    np.testing.assert_allclose(sim_time(np.array([100.5])), [0.5])    # one pair: rate 1
    sim_time.add(101.0, 2.0)                                          # lock-step at 2x
    np.testing.assert_allclose(sim_time(np.array([100.25, 101.5, 99.0])), [0.5, 3.0, -1.0])
    sim_time.add(102.0, 0.1)                                          # sim restarted
    np.testing.assert_allclose(sim_time(np.array([102.5])), [0.6])


def test_bus_load_meter_counts_each_bus_in_bits_against_its_bitrate():
    meter = BusLoadMeter({"vcan0": ("arm", BitRates(1_000_000)),
                          "vcan1": ("wrist", BitRates(500_000))}, now=0.0)
    for _ in range(100):
        meter.on_message_received(can.Message(arbitration_id=0x181, data=bytes(8),
                                              channel="vcan0", is_extended_id=False))
    meter.on_message_received(can.Message(arbitration_id=0x80, data=b"", channel="vcan1",
                                          is_extended_id=False))
    meter.on_message_received(can.Message(arbitration_id=0x80, channel="elsewhere"))
    loads = {load.bus: load for load in meter.take(until=0.1)}
    assert loads["arm"].frames_per_second == pytest.approx(1000)
    assert loads["arm"].nominal == pytest.approx(1000 * 111 / 1e6)     # 47 + 64 bits a frame
    assert loads["arm"].worst_case == pytest.approx(1000 * 135 / 1e6)  # + 24 stuff bits
    assert loads["wrist"].nominal == pytest.approx(10 * 47 / 5e5)
    assert meter.unknown_channel_frames == 1
    assert all(load.frames_per_second == 0 for load in meter.take(until=0.2))


def test_a_stamped_meter_counts_each_frame_in_the_interval_its_timestamp_falls_in():
    """hil viz's meter (its buses stamp frames with the senders' clocks): a frame heard late
    is counted in its own interval, one stamped past the interval waits for the next, and a
    stamp on another clock (a replayed log's) is counted on arrival."""
    now = time.time()
    meter = BusLoadMeter({"vcan0": ("arm", BitRates(1_000_000))}, now=now - 1.0,
                         by_timestamp=True)

    def heard(stamp: float) -> None:
        meter.on_message_received(can.Message(timestamp=stamp, arbitration_id=0x181,
                                              data=bytes(8), channel="vcan0",
                                              is_extended_id=False))

    for _ in range(10):
        heard(now - 0.9)                     # in the first interval
        heard(now - 0.2)                     # in the second
    heard(now - 1e6)                         # another clock: the first take counts it
    (first,) = meter.take(until=now - 0.5)
    assert first.interval == pytest.approx(0.5)
    assert first.frames_per_second == pytest.approx(11 / 0.5)
    heard(now - 0.7)                         # late: its interval was taken, so the next
    (second,) = meter.take(until=now)
    assert second.frames_per_second == pytest.approx(11 / 0.5)
    assert meter.take(until=now + 1.0)[0].frames_per_second == 0


def test_bus_time_rows_of_a_lock_step_run_are_its_load_up_to_the_last_cycle_and_after():
    """Lock-step at 2x (a 2 ms cycle every wall ms): 100 % measured on the wall is 50 % of
    bus time; the rows up to the run's last cycle go merged on bus time, at the end too, not
    diluted by the last row past it (the visualiser's, to its stop), which goes on the wall's
    seconds; rows covered by cycles but short of WINDOW wait for the next."""
    loads = BusTimeLoads()
    loads.cycles(np.arange(0.0, 1.0, 0.001), period=0.002)
    for k in range(10):
        loads.add(0.1 * k, 0.1 * (k + 1), [100.0, 120.0])
    assert loads.ready(now=1.0) == ([0.9], [[50.0, 60.0]])       # the last not covered yet
    loads.cycles(np.arange(1.0, 1.25, 0.001), period=0.002)     # the run's last cycles
    loads.add(1.0, 1.2, [100.0, 120.0])
    assert loads.ready(now=1.3) == ([], [])                      # short of WINDOW: waits
    loads.add(1.2, 3.7, [2.0, 2.4])                              # to the visualiser's stop
    times, rows = loads.ready(now=3.7, final=True)
    np.testing.assert_allclose(rows[0], [50.0, 60.0], rtol=0.01)
    np.testing.assert_allclose(times, [1.2, 3.7])
    # its 50 cycles on bus time (0.1 s), the wall's seconds after the last (1.249 s)
    assert rows[1][0] == pytest.approx(2.0 * 2.5 / (0.1 + 3.7 - 1.249), rel=0.01)


@pytest.mark.parametrize("switch", [True, False])
def test_the_meter_counts_an_fd_frames_data_phase_at_the_data_rate_as_the_estimate_does(
        switch):
    rates = BitRates(1_000_000, 5_000_000)
    meter = BusLoadMeter({"can0": ("arm", rates)}, now=0.0)
    for _ in range(100):
        meter.on_message_received(can.Message(
            arbitration_id=0x01, data=bytes(8), is_fd=True, bitrate_switch=switch,
            channel="can0", is_extended_id=False))
    (load,) = meter.take(until=0.1)
    estimate = bus_load(rates.nominal, [FrameSpec(0x01, 8, 1000, fd=True,
                                                  bitrate_switch=switch)], rates.data)
    assert load.worst_case == pytest.approx(estimate.worst_ratio)
    assert load.nominal == pytest.approx(estimate.nominal_ratio)


@pytest.mark.parametrize("suffix, named", [(".blf", False), (".log", True)])
@pytest.mark.parametrize("interface", ["virtual", "hil-virtual"])   # a Notifier; delivered as
def test_the_can_log_holds_every_frame_as_sent_its_channels_numbered_where_the_format_does(
        tmp_path, suffix, named, interface):                         # they come (deliver_to)
    # channels ending in digits past BLF's 16-bit channel number: python-can's writer reads
    # a name's trailing digits as its number (can.util.channel2int)
    tag = f"{suffix[1:]}-{tmp_path.name}"
    channels = {"arm": f"log-arm-{tag}/700001", "wrist": f"log-wrist-{tag}/700002"}
    senders = {name: can.Bus(interface=interface, channel=c, fd=True)
               for name, c in channels.items()}
    watched = {name: can.Bus(interface=interface, channel=c, fd=True)
               for name, c in channels.items()}
    path = tmp_path / f"run.can{suffix}"
    monitor = BusMonitor(watched, channels, {"arm": BitRates(1_000_000, 5_000_000), "wrist": BitRates(1_000_000, 5_000_000)},
                         path)
    sent = []
    for k in range(200):
        name = ("arm", "wrist")[k % 2]
        fd = k % 3 == 0                              # CAN FD frames of 64 bytes, BRS on some
        frame = can.Message(arbitration_id=0x180 + k % 7,
                            data=bytes([k % 256, k // 256, 7]) * (21 if fd else 1)
                            + bytes(fd), is_fd=fd, bitrate_switch=fd and k % 2 == 0,
                            is_extended_id=k % 5 == 0, timestamp=1000.0 + k * 1e-4)
        senders[name].send(frame)
        sent.append((name, frame))
    time.sleep(0.5)
    monitor.close()
    for bus in senders.values():
        bus.shutdown()
    logged = list(can.LogReader(path))
    assert monitor.channel_numbers == ({} if named else {"arm": 1, "wrist": 2})
    assert len(logged) == len(sent)

    def fields(f: can.Message) -> tuple:
        return (f.arbitration_id, bytes(f.data), f.is_extended_id, f.dlc, f.is_fd,
                f.bitrate_switch)

    for name in channels:        # each bus in its order (a notifier thread per bus)
        channel = channels[name] if named else monitor.channel_numbers[name]
        mine = [frame for bus, frame in sent if bus == name]
        back = [frame for frame in logged if frame.channel == channel]
        assert [fields(f) for f in back] == [fields(f) for f in mine]


def recorder_actuators(robot) -> dict[str, tuple[str, ...]]:
    """Each actuator of the robot and the joints it moves, as the recorder takes them."""
    return {a.name: tuple(j.name for j in t.joints)
            for t in robot.transmissions for a in t.actuators}


def saved_recorder(tmp_path, robot, xacro, package_path):
    """A recording saved to tmp_path/run.rrd and a RunRecorder of ``robot`` on it, its static
    data logged: (recording, recorder, path)."""
    urdf = tmp_path / f"{robot.name}.urdf"
    urdf.write_bytes(ET.tostring(read_robot_source(xacro, package_path).root))
    recording = rr.RecordingStream("hil-test")
    path = tmp_path / "run.rrd"
    recording.save(str(path))
    recorder = RunRecorder(recording, robot, urdf, recorder_actuators(robot), ("arm", "wrist"))
    recorder.log_static()
    return recording, recorder, path


@pytest.fixture
def recorded(tmp_path, pigot, package_path):
    """A pigot run of 4 batches (one lost in transit), recorded to an .rrd and read back."""
    recording, recorder, path = saved_recorder(tmp_path, pigot, PIGOT_XACRO, package_path)
    actuators = recorder_actuators(pigot)
    recorder.log_clock(0.0, 0.0)
    joints = tuple(j.name for j in pigot.driven_joints)
    batches = make_batches(joints, tuple(actuators), 4, 25,
                           states=lambda c: "SWITCHED ON" if c <= 30 else "OPERATION ENABLED")
    for index, batch in enumerate(batches):
        if index != 2:                       # batch 2 never arrives
            recorder.log_samples(batch)
    fault_at = batches[1].wall_time[5], batches[1].control_time[5]
    recorder.log_diagnostic(DiagnosticStatus("ERROR", "drive node 2 (arm_rot_2) is in FAULT",
                                       *fault_at))
    recorder.log_diagnostic(DiagnosticStatus("OK", "fault reset", fault_at[0] + 1, None))
    recorder.flush()                         # the poses waiting to be grouped
    recording.flush()
    recording.disconnect()
    rows = collections.Counter()
    values = collections.defaultdict(list)
    static = set()
    for chunk in rerun.chunk.RrdReader(path).store().stream():
        if chunk.is_static:
            static.add(chunk.entity_path)
        else:
            rows[chunk.entity_path] += chunk.num_rows
            values[chunk.entity_path].append(chunk.to_record_batch())
    return recorder, joints, rows, values, static


def cycle_values(values) -> np.ndarray:
    """The rows of ``/cycle`` as logged (cycles x series)."""
    return np.concatenate([np.array(b.column("Scalars:scalars").to_pylist())
                           for b in values["/cycle"]])


def test_recorder_logs_every_cycle_of_every_axis_and_counts_the_lost_batch(recorded):
    recorder, joints, rows, values, _ = recorded
    assert (recorder.cycles_logged, recorder.cycles_lost) == (75, 25)
    assert rows["/cycle"] == 75
    cycles = cycle_values(values)
    series = recorder.series
    assert cycles.shape == (75, len(series)) == (75, 6 * len(joints) + 7 + 2)
    reference = cycles[:, series.joint("arm_rot_1", "reference")]
    measured = cycles[:, series.joint("arm_rot_1", "measured")]
    # cycles 1..50 and 76..100, none twice, none invented (4-byte floats: to their precision)
    np.testing.assert_allclose(np.sort(measured), np.r_[1:51, 76:101], rtol=1e-7)
    np.testing.assert_allclose(reference - measured, 0.01, atol=1e-5)
    np.testing.assert_allclose(cycles[:, series.joint("arm_rot_1", "error")], 0.01, rtol=1e-5)
    assert not np.isnan(cycles[:, series.torque("arm_rot_1_motor")]).any()


def test_every_signal_of_a_cycle_shares_one_row_of_rerun_scalars(recorded):
    """The layout's point: a cycle is one row of one entity (its row id and three times
    once), its values Float64 as rerun's Scalar component declares them (rounded to 4-byte
    floats: the low bits compress away), its series named with their units."""
    recorder, joints, _, values, static = recorded
    (batch, *_) = values["/cycle"]
    assert str(batch.schema.field("Scalars:scalars").type) == "list<item: double>"
    row = np.array(batch.column("Scalars:scalars").to_pylist()[0])
    assert np.array_equal(row.astype(np.float32).astype(np.float64), row, equal_nan=True)
    assert {"wall_time", "control_time", "sim_time"} <= set(batch.schema.names)
    names = recorder.series.names()
    assert names[:3] == ["arm_rot_1 reference [rad]", "arm_rot_1 measured [rad]",
                         "arm_rot_1 error [rad]"]
    assert "finger_pri_1 effort [N]" in names and names[-2:] == ["period [ms]",
                                                                "round trip [ms]"]
    assert "/cycle" in static                               # the series' names and styles


def test_recorder_logs_drive_states_only_when_they_change(recorded):
    _, _, rows, values, _ = recorded
    assert rows["/drives/arm_rot_1_motor/state"] == 2      # SWITCHED ON, OPERATION ENABLED
    states = [s for b in values["/drives/arm_rot_1_motor/state"]
              for s in b.column(b.schema.names[-1]).to_pylist()]
    assert [s[0] if isinstance(s, list) else s for s in states] == [
        "SWITCHED ON", "OPERATION ENABLED"]


def test_recorder_puts_diagnostics_on_the_timelines_with_their_level(recorded):
    _, _, rows, values, _ = recorded
    assert rows["/diagnostics"] == 2
    batches = values["/diagnostics"]
    logged = [(b.column("TextLog:text").to_pylist(), b.column("TextLog:level").to_pylist())
              for b in batches]
    assert logged == [([["drive node 2 (arm_rot_2) is in FAULT"]], [["ERROR"]]),
                      ([["fault reset"]], [["INFO"]])]
    control_time = batches[0].column("control_time").to_pylist()[0]
    assert control_time.total_seconds() == pytest.approx(31 * 0.002)     # cycle 31
    assert "control_time" not in batches[1].schema.names    # the reset did not say its time
    assert all({"wall_time", "sim_time"} <= set(b.schema.names) for b in batches)


def test_recorder_poses_the_3d_robot_including_its_mimic_joint(recorded):
    _, _, rows, values, static = recorded
    children = [frame for batch in values["/joints"]
                for frame in batch.column("Transform3D:child_frame").to_pylist()]
    children = [c[0] if isinstance(c, list) else c for c in children]
    assert children.count("arm_link_1") >= 1
    assert children.count("finger_link_2") == children.count("finger_link_1")   # the mimic
    assert rows["/joints"] == len(children)
    links = {"body_link", "arm_link_1", "arm_link_6", "finger_link_1", "finger_link_2"}
    drawn = {path.split("/")[4] for path in static
             if path.startswith("/robot/pigot/visual_geometries/")}
    assert links <= drawn


def test_robots_sharing_a_recording_each_keep_their_entities_frames_and_bus_loads(
        tmp_path, pigot, ur3, package_path):
    recording = rr.RecordingStream("hil-test")
    path = tmp_path / "two.rrd"
    recording.save(str(path))
    recorders = {}
    for robot, xacro in ((pigot, PIGOT_XACRO), (ur3, UR3_XACRO)):
        urdf = tmp_path / f"{robot.name}.urdf"
        urdf.write_bytes(ET.tostring(read_robot_source(xacro, package_path).root))
        actuators = {a.name: tuple(j.name for j in t.joints)
                     for t in robot.transmissions for a in t.actuators}
        estimates = {"arm": 0.5, "wrist": 0.6} if robot is ur3 else {}
        recorder = recorders[robot.name] = RunRecorder(
            recording, robot, urdf, actuators, ("arm", "wrist"), namespaced=True,
            bench=BenchParts(bus_estimates=estimates))
        recorder.log_static()
        recorder.log_clock(0.0, 0.0)
        joints = tuple(j.name for j in robot.driven_joints)
        for batch in make_batches(joints, tuple(actuators), 2, 10):
            recorder.log_samples(batch)
    assert recorders["ur3"].monitor_names == {"ur3/arm": "arm", "ur3/wrist": "wrist"}
    # one monitor of all four buses: each robot logs its own two, none of the other's
    loads = [MeasuredLoad(name, 100.0, load, load) for name, load in
             (("ur3/arm", 0.1), ("ur3/wrist", 0.2), ("pigot/arm", 0.3), ("pigot/wrist", 0.4))]
    for recorder in recorders.values():
        recorder.log_bus_load(1.0, loads)
        recorder.flush()
    recorders["ur3"].log_diagnostic(DiagnosticStatus("ERROR", "drive node 2 is in FAULT", 1.0,
                                                     0.5))
    recording.flush()
    recording.disconnect()
    from hil.visualisation.review import review
    reviewed = review([path])                     # each robot's run, and its diagnostics
    assert [run.robot for run in reviewed.runs] == ["pigot", "ur3"]
    assert [d.text for d in reviewed.diagnostics] == ["drive node 2 is in FAULT"]
    rows, static, frames, load_logged = collections.Counter(), set(), set(), {}
    for chunk in rerun.chunk.RrdReader(path).store().stream():
        if chunk.is_static:
            static.add(chunk.entity_path)
            continue
        rows[chunk.entity_path] += chunk.num_rows
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("child_frame"):
                frames.update(f for row in batch.column(name).to_pylist() for f in row)
            if "/bus/" in chunk.entity_path:
                if name == "Scalars:scalars":
                    load_logged[chunk.entity_path] = batch.column(name).to_pylist()[0]
    assert rows["/pigot/cycle"] == 20 and rows["/ur3/cycle"] == 20
    assert not any(p.startswith(("/cycle", "/drives", "/joints")) for p in rows)
    assert set(load_logged) == {"/ur3/bus/load", "/pigot/bus/load"}
    # each bus: nominal, worst-case stuffing, the config's estimate (none given: NaN)
    assert load_logged["/ur3/bus/load"] == pytest.approx([10, 10, 50, 20, 20, 60])
    assert load_logged["/pigot/bus/load"] == pytest.approx([30, 30, np.nan, 40, 40, np.nan],
                                                           nan_ok=True)
    # each robot's model under its name, its frames named after it: no link shared
    assert any(p.startswith("/pigot/visual_geometries/arm_link_6") for p in static)
    assert any(p.startswith("/ur3/visual_geometries/") for p in static)
    assert "pigot/arm_link_1" in frames and "ur3/link1" in frames
    assert all(f.startswith(("pigot/", "ur3/")) for f in frames)


@pytest.mark.parametrize("xacro", [PIGOT_XACRO, UR3_XACRO], ids=["pigot", "ur3"])
def test_demo_goal_moves_every_joint_inside_its_limits_and_speed(xacro, package_path):
    from hil.description import load_description
    robot = load_description(xacro, package_path)
    names = [j.name for j in robot.driven_joints]
    current = [min(max(0.0, robot.joint(n).limits.lower), robot.joint(n).limits.upper)
               for n in names]
    current[0] = robot.joint(names[0]).limits.upper        # resting on a limit
    goal = demo_goal(robot, names, current)
    previous, start = np.array(current), 0.0
    for point in goal.points:
        positions = np.array(point.positions)
        for name, position in zip(names, positions):
            limits = robot.joint(name).limits
            assert limits.lower < position < limits.upper, name
        peak = 1.5 * np.abs(positions - previous) / (point.time_from_start - start)
        limit = np.array([robot.joint(n).limits.velocity for n in names])
        assert np.all(peak <= limit + 1e-9)
        previous, start = positions, point.time_from_start
    swings = np.ptp([p.positions for p in goal.points], axis=0)
    assert np.all(swings > 0.01), dict(zip(names, swings))
    for name, column in zip(names, np.array([p.positions for p in goal.points]).T):
        joint = robot.joint(name)
        if joint.type.name == "PRISMATIC":            # the gripper opens and closes fully
            span = joint.limits.upper - joint.limits.lower
            assert column.max() > joint.limits.upper - 0.1 * span
            assert column.min() < joint.limits.lower + 0.1 * span


def test_viz_refuses_can_log_without_can(tmp_path):
    from hil.cli import main
    assert main(["viz", str(PIGOT_CONFIG), "--no-can", "--can-log", str(tmp_path / "x.log"),
                 "--save", str(tmp_path / "x.rrd")]) == 1


@pytest.mark.slow
def test_review_gives_each_joints_tracking_as_the_controllers_samples_of_the_run(
        tmp_path, ur3, package_path):
    """Issue 46: `hil review --json`'s per-joint tracking is the run's: the same figures as
    computed (as hil bench computes them) from the samples the controller published."""
    from hil.bus_config import load_bus_config
    from hil.controllers import TrajectoryGoal, TrajectoryPoint
    from hil.messaging.zenoh_api import RunSubscriber, TrajectoryActionClient
    from hil.realtime import LOCK_STEP
    from hil.stack import running_stack
    from hil.visualisation.review import review

    config = load_bus_config(ROOT / "bus_config" / "ur3.yaml", package_path)
    samples: list[ControlSamples] = []
    with running_stack(config, LOCK_STEP) as stack:
        subscriber = RunSubscriber(stack.zenoh, "ur3", samples.append, lambda *_: None,
                                   lambda *_: None)
        client = TrajectoryActionClient(stack.zenoh, "ur3")
        goal = TrajectoryGoal(("joint2", "joint3"), (TrajectoryPoint(1.0, (0.3, -0.2),
                                                                     (0.0, 0.0)),))
        client.wait_result(client.send_goal(goal), timeout=60)
        time.sleep(0.3)
        subscriber.close()
        client.close()
    recording, recorder, path = saved_recorder(tmp_path, ur3, UR3_XACRO, package_path)
    for batch in samples:
        recorder.log_samples(batch)
    recorder.flush()
    recording.flush()
    recording.disconnect()

    (run,) = review([path]).runs
    error = np.concatenate([s.reference - s.position for s in samples])
    assert run.cycles == len(error)
    for k, joint in enumerate(samples[0].joint_names):
        found = run.joints[joint]
        assert found.rms == pytest.approx(np.sqrt(np.mean(error[:, k] ** 2)), rel=1e-5, abs=1e-9)
        assert found.max == pytest.approx(np.abs(error[:, k]).max(), rel=1e-5, abs=1e-9)
    assert run.joints["joint2"].max > 1e-4                 # the move's error, not nothing


def test_review_counts_each_processes_stalls_and_their_longest(tmp_path, pigot, package_path):
    from hil.realtime.stalls import Stall
    from hil.visualisation.review import review

    recording, recorder, path = saved_recorder(tmp_path, pigot, PIGOT_XACRO, package_path)
    joints = tuple(j.name for j in pigot.driven_joints)
    for batch in make_batches(joints, tuple(recorder_actuators(pigot)), 1, 10):
        recorder.log_samples(batch)
    for process, length in (("sim", 0.007), ("control", 0.012), ("sim", 0.031)):
        recorder.log_stall(Stall(process, 1.0, length))
    for k in range(5000):                       # a loaded host: a row a second, not a point
        recorder.log_stall(Stall("transport", 2.0 + k * 0.002, 0.003 + k * 1e-7))
    recorder.flush()
    recording.flush()
    recording.disconnect()
    (run,) = review([path]).runs
    assert run.stalls["sim"] == (2, pytest.approx(31.0))
    assert run.stalls["control"] == (1, pytest.approx(12.0))
    assert run.stalls["transport"] == (5000, pytest.approx(3.4999, abs=1e-3))
    rows, _ = read_rrd(path)
    assert rows["/loop/stalls/transport"] <= 11             # 10 s of stalls, a row a second


ARM_WITHOUT_MESHES = """<robot name="arm">
  <link name="base"><visual><geometry><mesh filename="package://gone/base.stl"/></geometry>
    </visual><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0"
    ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><visual><geometry><mesh filename="package://gone/upper.stl"/></geometry>
    </visual><inertial><origin xyz="0 0 0.15"/><mass value="1"/><inertia ixx="0.01"
    iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="fore"><visual><geometry><mesh filename="package://gone/fore.stl"/></geometry>
    </visual><inertial><origin xyz="0.1 0 0"/><mass value="1"/><inertia ixx="0.01"
    iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
</robot>
"""


def test_a_robot_without_its_meshes_is_drawn_as_its_kinematic_skeleton(tmp_path):
    """Meshes not found: each link drawn as bones to its child joints' origins (to its
    centre of mass at the chain's end) and its joint along its axis, where the plant's
    inertia boxes would float apart, each at its link's centre of mass."""
    from hil.description import PackagePath, load_description
    from hil.visualisation.urdf_export import viewer_urdf

    source = tmp_path / "arm.urdf"
    source.write_text(ARM_WITHOUT_MESHES)
    robot = load_description(source, PackagePath(()))
    drawn = {link.get("name"): link for link in ET.fromstring(viewer_urdf(robot)).iter("link")}

    def cylinders(link: str) -> list[tuple[tuple[float, ...], str, float]]:
        return [(tuple(map(float, v.find("origin").get("xyz").split())),
                 v.find("origin").get("rpy"), float(v.find("geometry/cylinder").get("length")))
                for v in drawn[link].iter("visual")]

    # bones: base to the shoulder (0.1 up), upper arm to the elbow (0.3 up), forearm to its
    # centre of mass (0.1 along x: pitched a quarter turn); joints along y (pitched, yawed)
    assert ((0.0, 0.0, 0.05), "0.0 0.0 0.0", pytest.approx(0.1)) in cylinders("base")
    assert ((0.0, 0.0, 0.15), "0.0 0.0 0.0", pytest.approx(0.3)) in cylinders("upper")
    (bone, joint) = cylinders("fore")
    assert bone[0] == pytest.approx((0.05, 0.0, 0.0)) and bone[2] == pytest.approx(0.1)
    assert [float(a) for a in bone[1].split()] == pytest.approx([0, math.pi / 2, 0])
    assert [float(a) for a in joint[1].split()] == pytest.approx([0, math.pi / 2, math.pi / 2])
    assert all(link.find("visual/geometry/box") is None for link in drawn.values())


def test_the_seed_robots_stand_in_boxes_are_drawn_as_skeletons(ur3, pigot, tmp_path):
    """The shipped seeds draw each link as its equivalent inertia box at its centre of mass
    (their meshes are not shipped): the viewer takes those for stand-ins, a skeleton each,
    in a URDF rerun's own loader reads."""
    from rerun.urdf import UrdfTree

    from hil.visualisation.urdf_export import viewer_urdf

    for robot in (ur3, pigot):
        text = viewer_urdf(robot)
        drawn = ET.fromstring(text)
        assert next(drawn.iter("box"), None) is None, robot.name
        assert sum(1 for _ in drawn.iter("cylinder")) >= len(robot.joints), robot.name
        path = tmp_path / f"{robot.name}.urdf"
        path.write_bytes(text)
        UrdfTree.from_file_path(path, "robot")          # raises on what it cannot read


def test_review_names_the_robot_of_a_recording_and_puts_its_times_on_one_clock(
        tmp_path, pigot, package_path, capsys):
    """Issue 64: `hil review --json` gave "robot": "" for a one-robot recording (its entities
    at the root: its name is its model's, /robot/<name>), and the largest error was "at
    7.592 s" of a "6.958 s" run: a time on the controller's clock beside a span of it. The
    span is given on that clock too (the first recorded cycle is not the clock's zero)."""
    import json

    from hil.cli import main

    recording, recorder, path = saved_recorder(tmp_path, pigot, PIGOT_XACRO, package_path)
    joints = tuple(j.name for j in pigot.driven_joints)
    for batch in make_batches(joints, tuple(recorder_actuators(pigot)), 4, 25)[1:]:
        recorder.log_samples(batch)                 # the first 25 cycles never recorded
    recorder.flush()
    recording.flush()
    recording.disconnect()
    assert main(["review", str(path), "--json"]) == 0
    (run,) = json.loads(capsys.readouterr().out)["runs"]
    assert run["robot"] == "pigot"
    assert run["first_control_time_s"] == pytest.approx(0.052)
    assert run["last_control_time_s"] == pytest.approx(0.2)
    assert run["duration_s"] == pytest.approx(0.148)
    for joint in run["joints"].values():
        assert run["first_control_time_s"] <= joint["max_at_control_time_s"] \
            <= run["last_control_time_s"]
    assert main(["review", str(path), "--no-viewer"]) == 0
    said = capsys.readouterr().out
    assert "pigot: 75 cycles over 0.148 s of control time, 0.052 s to 0.200 s" in said


def test_review_web_says_what_a_headless_browser_needs(tmp_path, pigot, package_path,
                                                        monkeypatch, capsys):
    """Issue 64: `hil review --web` in `chromium --headless --screenshot` showed only
    "Loading": the screenshot is taken at the page's load, before the viewer's wasm compiled
    and streamed the recording (measured: after 35 s through DevTools the run showed)."""
    import hil.cli.review
    from hil.cli import main

    recording, recorder, path = saved_recorder(tmp_path, pigot, PIGOT_XACRO, package_path)
    recording.flush()
    recording.disconnect()
    served = []
    monkeypatch.setattr(hil.cli.review, "run_foreground", lambda command: served.append(
        command) or 0)
    assert main(["review", str(path), "--web", "--web-port", "9300"]) == 0
    said = capsys.readouterr().out
    assert "web viewer at http://127.0.0.1:9300/?url=rerun%2Bhttp://127.0.0.1:9301/proxy" in said
    assert "needs WebGL" in said and "`chromium --screenshot` shoots at once" in said
    assert served and "--serve-web" in served[0]


def test_a_stop_signal_ends_the_visualiser_whose_handler_outlasts_its_wait():
    """A signal whose handler outlasts the loop's wait for batches (a loaded host), then no
    more batches (its senders gone, as when hil up is SIGKILLed): the loop still ends once
    stopped. On CPython 3.11 a SimpleQueue's get(timeout) waited for the next item for ever
    after such a handler, and a CI run's visualiser outlived its hil up."""
    node = VizNode([], session=None)             # no robot: no Zenoh session needed

    def slow_stop(signum, frame) -> None:
        time.sleep(0.2)                          # longer than the wait (50 ms)
        threading.Thread(target=node.stop).start()

    def give_up(signum, frame) -> None:
        raise TimeoutError("the visualiser's loop did not end")

    previous = {signal.SIGUSR1: signal.signal(signal.SIGUSR1, slow_stop),
                signal.SIGUSR2: signal.signal(signal.SIGUSR2, give_up)}
    stopping = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGUSR1))
    rescue = threading.Timer(10.0, os.kill, (os.getpid(), signal.SIGUSR2))
    try:
        stopping.start()
        rescue.start()
        started = time.monotonic()
        node.run()                               # the main thread: where handlers run
        assert time.monotonic() - started < 5.0
    finally:
        stopping.cancel()
        rescue.cancel()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
