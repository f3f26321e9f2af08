"""The protocol-free drive core and the CiA 402 state machine, without a bus."""

from __future__ import annotations

import math

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from hil.protocols.cia402.state import Cia402StateMachine, State, int16, int32, statusword
from hil.drives.core import DriveCore
from hil.drives.definitions import DriveParameters, Fault, Mode, Power, round_half_even
from hil.drives.group import CoreGroup
from conftest import TEST_MOTOR_DRIVE

DT = 0.001


def parameters(**changes) -> DriveParameters:
    return DriveParameters(**{**TEST_MOTOR_DRIVE, **changes})


class Motor:
    """A bare motor shaft: J dw/dt = torque (motor side)."""

    def __init__(self, inertia=1e-3):
        self.inertia, self.position, self.velocity = inertia, 0.0, 0.0

    def run(self, core: DriveCore, seconds: float) -> None:
        for _ in range(round(seconds / DT)):
            core.measure(self.position, self.velocity)
            torque = core.update(DT)
            self.velocity += torque / self.inertia * DT
            self.position += self.velocity * DT


def test_csp_follows_interpolated_setpoints():
    core, motor = DriveCore(parameters()), Motor()
    core.set_cycle(0.01)
    core.enable()
    for k in range(1, 101):
        core.new_setpoint(position=0.05 * k, now=0.0)
        motor.run(core, 0.01)
    motor.run(core, 0.5)
    assert motor.position == pytest.approx(5.0, abs=2 * 2 * math.pi / 4096)
    assert core.status().target_reached


def test_a_group_of_cores_steps_each_as_alone_and_orders_torques_by_actuator():
    """CoreGroup: each core measured and updated as on its own, its torque at its plant
    actuator's place; an actuator no drive drives gets none."""
    alone = [DriveCore(parameters()) for _ in range(2)]
    grouped = [DriveCore(parameters()) for _ in range(2)]
    group = CoreGroup(3)
    for core, actuator in zip(grouped, (2, 0)):
        group.add(core, actuator)
    for core in alone + grouped:
        core.enable()
    for k in range(1, 50):
        positions, velocities = [0.001 * k, 0.7, -0.002 * k], [0.1, 0.0, -0.2]
        for core, target in zip(alone + grouped, (0.3, -0.2, 0.3, -0.2)):
            core.new_setpoint(position=target, now=0.0)
        alone[0].measure(positions[2], velocities[2], DT)
        alone[1].measure(positions[0], velocities[0], DT)
        group.measure(positions, velocities, DT)
        torques = group.update(DT)
        assert torques == [alone[1].update(DT), 0.0, alone[0].update(DT)]
    assert torques[0] != 0.0 and torques[2] != 0.0


def test_torque_saturates_at_peak():
    core, motor = DriveCore(parameters()), Motor()
    core.enable()
    core.new_setpoint(position=40.0, now=0.0)
    core.set_cycle(1.0)
    motor.run(core, 0.002)
    assert abs(core.status().torque) <= 2.0


def test_following_error_faults_after_its_timeout():
    core, motor = DriveCore(parameters(peak_torque=0.01)), Motor()
    core.set_cycle(0.001)
    core.enable()
    core.new_setpoint(position=10.0, now=0.0)
    motor.run(core, 0.05)
    assert core.power is Power.FAULT and core.fault is Fault.FOLLOWING_ERROR
    assert Fault.FOLLOWING_ERROR in core.events
    core.reset_fault()
    assert core.power is Power.DISABLED and core.fault is None


def test_setpoints_beyond_position_limits_are_clamped_and_flagged():
    core, motor = DriveCore(parameters(following_error_limit=0.0)), Motor()
    core.set_cycle(0.01)
    core.enable()
    core.new_setpoint(position=80.0, now=0.0)
    assert core.status().internal_limit
    motor.run(core, 2.0)
    assert motor.position == pytest.approx(50.0, abs=0.01)


def test_leaving_the_position_range_faults():
    core, motor = DriveCore(parameters()), Motor()
    core.enable()
    core.set_mode(Mode.TORQUE)
    core.new_setpoint(torque=2.0, now=0.0)
    motor.run(core, 1.0)
    assert core.fault is Fault.POSITION_LIMIT


def test_watchdog_quick_stops_then_holds():
    core, motor = DriveCore(parameters()), Motor()
    core.set_mode(Mode.VELOCITY)
    core.enable()
    core.new_setpoint(velocity=20.0, now=0.0)
    motor.run(core, 0.3)
    core.check_watchdog(now=0.05)
    assert core.power is Power.ENABLED
    core.check_watchdog(now=0.2)
    assert core.power is Power.QUICK_STOP and Fault.CONTROLLER_SILENT in core.events
    motor.run(core, 0.3)                         # 20 rad/s at 500 rad/s^2: 40 ms
    assert core.status().stopped and abs(motor.velocity) < 0.05


def _leave_by_fault(core: DriveCore) -> None:
    core.raise_fault(Fault.FOLLOWING_ERROR)
    core.reset_fault()


@pytest.mark.parametrize("leave", [DriveCore.disable, DriveCore.quick_stop, _leave_by_fault],
                         ids=["disable", "quick-stop", "fault"])
def test_the_watchdog_counts_only_while_enabled(leave):
    """Issue 64: the time of the last setpoint before a disable tripped the watchdog at the
    next enable. The watchdog counts only while enabled (Ben Katz's mini-cheetah firmware,
    Hobbyking_Cheetah_Compact main.cpp: its timeout counter runs in motor mode only)."""
    core = DriveCore(parameters())                # watchdog 0.1 s
    core.set_mode(Mode.VELOCITY)
    core.enable()
    core.new_setpoint(velocity=0.0, now=0.0)
    leave(core)
    core.enable()
    core.check_watchdog(now=0.4)                  # enabled again 0.4 s later, no setpoint yet
    assert core.power is Power.ENABLED and Fault.CONTROLLER_SILENT not in core.events
    core.new_setpoint(velocity=0.0, now=0.41)
    core.check_watchdog(now=0.5)
    assert core.power is Power.ENABLED
    core.check_watchdog(now=0.52)                 # silent 0.11 s since the last setpoint
    assert core.power is Power.QUICK_STOP


def test_disabled_drive_with_brake_holds_against_load():
    core, motor = DriveCore(parameters()), Motor()
    core.measure(1.0, 0.0)
    core.disable()
    motor.position = 1.0
    motor.run(core, 0.2)
    assert motor.position == pytest.approx(1.0, abs=1e-3)


def test_state_machine_walks_to_operation_enabled_and_back():
    core = DriveCore(parameters())
    machine = Cia402StateMachine(core)
    assert machine.state is State.SWITCH_ON_DISABLED
    for word, state in ((0x06, State.READY_TO_SWITCH_ON), (0x07, State.SWITCHED_ON),
                        (0x0F, State.OPERATION_ENABLED), (0x07, State.SWITCHED_ON),
                        (0x0F, State.OPERATION_ENABLED), (0x02, State.QUICK_STOP_ACTIVE),
                        (0x0F, State.OPERATION_ENABLED), (0x00, State.SWITCH_ON_DISABLED)):
        machine.controlword(word)
        assert machine.state is state, hex(word)


def test_enable_operation_is_ignored_from_switch_on_disabled():
    machine = Cia402StateMachine(DriveCore(parameters()))
    machine.controlword(0x0F)
    assert machine.state is State.SWITCH_ON_DISABLED


def test_fault_reset_needs_a_rising_edge():
    core = DriveCore(parameters())
    machine = Cia402StateMachine(core)
    core.raise_fault(Fault.FOLLOWING_ERROR)
    assert machine.state is State.FAULT
    machine.controlword(0x80)
    assert machine.state is State.SWITCH_ON_DISABLED
    core.raise_fault(Fault.FOLLOWING_ERROR)
    machine.controlword(0x80)                    # bit 7 still high: no new edge
    assert machine.state is State.FAULT


@pytest.mark.parametrize("state, value", [
    (State.SWITCH_ON_DISABLED, 0x40), (State.READY_TO_SWITCH_ON, 0x21),
    (State.SWITCHED_ON, 0x23), (State.OPERATION_ENABLED, 0x27),
    (State.QUICK_STOP_ACTIVE, 0x07), (State.FAULT, 0x08)])
def test_statusword_matches_cia402_masks(state, value):
    word = statusword(state, DriveCore(parameters()).status(), 0)
    mask = 0x4F if state in (State.SWITCH_ON_DISABLED, State.FAULT) else 0x6F
    assert word & mask == value
    assert word & 0x0200                         # remote


def first_torque(core: DriveCore) -> float:
    """The torque of the first inner-loop step, the motor at rest at 0."""
    core.measure(0.0, 0.0)
    return core.update(DT)


def test_a_velocity_offset_is_the_csp_feed_forward_in_place_of_the_setpoints_difference():
    p = parameters()
    cycle, step = 0.01, 0.05
    derived, given = DriveCore(p), DriveCore(p)
    for core in (derived, given):
        core.set_cycle(cycle)
        core.enable()
    derived.new_setpoint(position=step, now=0.0)
    given.new_setpoint(position=step, now=0.0, velocity_ff=1.5)
    # velocity command = feed-forward + position_kp x (interpolated target - position)
    error = step * DT / cycle
    for core, feed_forward in ((derived, step / cycle), (given, 1.5)):
        velocity = feed_forward + p.position_kp * error
        assert first_torque(core) == pytest.approx(
            p.velocity_kp * velocity + p.velocity_ki * velocity * DT)


def test_offsets_add_to_the_velocity_and_torque_modes_targets():
    p = parameters()
    velocity_mode, torque_mode = DriveCore(p), DriveCore(p)
    velocity_mode.set_mode(Mode.VELOCITY)
    torque_mode.set_mode(Mode.TORQUE)
    for core in (velocity_mode, torque_mode):
        core.enable()
    velocity_mode.new_setpoint(velocity=2.0, velocity_ff=0.5, torque_ff=0.1, now=0.0)
    torque_mode.new_setpoint(torque=0.3, torque_ff=-0.1, now=0.0)
    assert first_torque(velocity_mode) == pytest.approx(
        p.velocity_kp * 2.5 + p.velocity_ki * 2.5 * DT + 0.1)
    assert first_torque(torque_mode) == pytest.approx(0.2)


def test_enabling_again_forgets_the_offsets():
    core = DriveCore(parameters())
    core.set_cycle(0.01)
    core.enable()
    core.new_setpoint(position=0.0, velocity_ff=3.0, torque_ff=0.2, now=0.0)
    core.disable()
    core.enable()
    assert first_torque(core) == 0.0


# --- homing (CiA 402 homing mode; hil.protocols.cia402.homing) ------------------------

def _homed(method: int, start: float = 1.0, limits=(-3.0, 3.0)):
    """(machine, motor) after a homing run of ``method`` from ``start`` (motor rad)."""
    from hil.protocols.cia402.homing import HomingSpeeds
    core, motor = DriveCore(parameters(position_limits=limits)), Motor()
    motor.position = start
    machine = Cia402StateMachine(core)
    core.set_cycle(0.01)
    core.set_mode(Mode.HOMING)
    motor.run(core, 0.01)
    for word in (0x06, 0x07, 0x0F):
        machine.controlword(word)
    machine.homing_method, machine.home_offset = method, 0.5
    machine.homing_speeds = HomingSpeeds(switch=20.0, zero=5.0, acceleration=200.0)
    machine.controlword(0x1F)                    # bit 4: homing operation start
    for _ in range(300):
        motor.run(core, 0.01)
        machine.after_update()
        if machine.homing_attained or machine.homing_error:
            break
    motor.run(core, 0.2)
    return machine, motor


@pytest.mark.parametrize("method, home", [
    (17, -3.0),      # the negative limit switch
    (18, 3.0),       # the positive one
    (1, 0.0),        # negative switch, then the first index pulse (encoder zero) above it
    (2, 0.0),        # positive switch, then the first index pulse below it
    (33, 0.0),       # the index pulse below the start
    (35, 1.0),       # where it stands
])
def test_homing_finds_the_switch_or_index_and_reads_the_home_offset_there(method, home):
    machine, motor = _homed(method)
    assert machine.homing_attained and not machine.homing_error
    assert motor.position == pytest.approx(home, abs=0.01)
    assert machine.core.status().position == pytest.approx(0.5, abs=0.01)
    bits = machine.mode_bits(machine.core.status())
    assert bits & 0x1000 and not bits & 0x2000   # homing attained, no error


def test_homing_to_an_index_pulse_past_a_limit_is_a_homing_error():
    machine, motor = _homed(34)                  # the next index above 1.0 is 2 pi > 3.0
    assert machine.homing_error and not machine.homing_attained
    assert machine.mode_bits(machine.core.status()) & 0x2000


def test_homing_on_a_switch_that_is_not_there_is_a_homing_error():
    machine, _ = _homed(17, limits=None)
    assert machine.homing_error


@given(st.floats(allow_nan=False, allow_infinity=False)
       | st.integers(-2**60, 2**60).map(lambda n: n / 2)
       | st.integers(-2**60, 2**60).map(lambda n: math.nextafter(n / 2, math.inf))
       | st.integers(-2**60, 2**60).map(lambda n: math.nextafter(n / 2, -math.inf)))
@example(0.49999999999999994)
@example(-0.49999999999999994)
@example(-0.0)
@example(2.0**53 + 2)
@example(-2.5)
@example(-3.5)
@example(2.5)
@example(3.5)
def test_the_compiled_cores_rounding_gives_what_round_gives_for_every_float(value):
    # the core and the CiA 402 objects round every measurement and every TPDO value with it:
    # a count off by one would change what a lock-step replay compares bit for bit
    assert round_half_even(value) == round(value)


@pytest.mark.parametrize("value, error", [(math.nan, ValueError), (math.inf, OverflowError),
                                          (-math.inf, OverflowError)])
def test_the_compiled_cores_rounding_refuses_what_round_refuses(value, error):
    with pytest.raises(error):
        round(value)
    with pytest.raises(error):
        round_half_even(value)


def test_integer_objects_saturate_at_their_type_and_round_halves_to_even():
    assert int32(2.0**40) == 2**31 - 1 and int32(-2.0**40) == -2**31
    assert int16(40000.0) == 2**15 - 1 and int16(-40000.0) == -2**15
    assert int32(2.5) == 2 and int32(-3.5) == -4 and int16(0.5) == 0
