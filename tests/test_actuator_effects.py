"""Each actuator effect of a bus config (``effects:``) against its closed form, on one
vertical axis behind a 10:1 gear: MuJoCo's own models in the plant (Coulomb and viscous
friction, delay; backlash and gear compliance as a second hinge) and the drive's
torque-speed line, encoder counts and velocity filter."""

from __future__ import annotations

import math

import can
import pytest

from hil.bus_config import load_bus_config
from hil.bus_config.types import ActuatorEffects
from hil.cli import main
from hil.description import load_description
from hil.drives.core import DriveCore
from hil.drives.definitions import DriveParameters, Mode
from hil.errors import HilError
from hil.plant import Plant
from hil.simulator import Simulator
from conftest import TEST_MOTOR_DRIVE, TESTS

ONE_AXIS = TESTS / "fixtures" / "one_axis.urdf"
STEP = 0.001


@pytest.fixture(scope="module")
def one_axis():
    return load_description(ONE_AXIS)


def plant_with(description, **effects) -> Plant:
    return Plant(description, timestep=STEP, effects={"yaw_motor": ActuatorEffects(**effects)})


def run(plant: Plant, torque: float, seconds: float) -> float:
    """The motor speed after ``seconds`` of a constant motor ``torque`` from rest."""
    plant.set_motor_torques([torque])
    plant.step(round(seconds / STEP))
    return float(plant.motor_velocities()[0])


def test_viscous_friction_settles_the_motor_where_b_times_speed_is_its_torque(one_axis):
    speed = run(plant_with(one_axis, viscous_friction=0.01), 0.05, 10.0)
    assert speed == pytest.approx(0.05 / 0.01, rel=1e-3)              # w = tau / b


def test_coulomb_friction_holds_below_breakaway_and_takes_its_share_above(one_axis):
    assert abs(run(plant_with(one_axis, coulomb_friction=0.02, viscous_friction=0.01),
                   0.015, 2.0)) < 1e-3                                 # |tau| < c: at rest
    speed = run(plant_with(one_axis, coulomb_friction=0.02, viscous_friction=0.01), 0.05, 10.0)
    assert speed == pytest.approx((0.05 - 0.02) / 0.01, rel=1e-2)     # w = (tau - c) / b


def test_a_delay_applies_the_commanded_torque_exactly_that_many_steps_later(one_axis):
    plant = plant_with(one_axis, delay=0.004)
    plant.set_motor_torques([0.1])
    applied = []
    for _ in range(6):
        plant.step()
        applied.append(float(plant.motor_torques()[0]))
    assert applied == [0.0, 0.0, 0.0, 0.0, 0.1, 0.1]                  # 4 steps of 1 ms


def test_a_coupled_motors_friction_acts_on_its_tendon_the_motor_position(coupled):
    plant = Plant(coupled, effects={"wrist_right_motor": ActuatorEffects(coulomb_friction=0.01)})
    losses = plant.model.tendon_frictionloss
    tendon = plant.model.tendon("wrist_right_motor_tendon").id
    assert losses[tendon] == 0.01 and not any(losses[t] for t in range(len(losses))
                                              if t != tendon)


def test_no_effects_is_the_perfect_motor(one_axis):
    plant = plant_with(one_axis)
    plant.set_motor_torques([0.1])
    plant.step()
    assert float(plant.motor_torques()[0]) == 0.1


def measured_torque(parameters: DriveParameters, speed: float, torque: float) -> float:
    """The torque a drive in torque mode applies, commanded ``torque``, at motor ``speed``."""
    core = DriveCore(parameters)
    core.set_mode(Mode.TORQUE)
    core.enable()
    core.new_setpoint(torque=torque, now=0.0)
    core.measure(0.0, speed)
    return core.update(STEP)


@pytest.mark.parametrize("speed, command, expected", [
    (0.0, 5.0, 2.0),                    # at rest: the peak
    (25.0, 5.0, 2.0 * (1 - 25 / 100)),  # driving at a quarter of the no-load speed
    (100.0, 5.0, 0.0),                  # at the no-load speed: nothing left
    (50.0, -5.0, -2.0),                 # braking: the full peak
    (50.0, 0.5, 0.5),                   # under the line: as commanded
])
def test_the_torque_speed_line_caps_driving_torque_at_peak_times_one_less_speed_share(
        speed, command, expected):
    parameters = DriveParameters(**{**TEST_MOTOR_DRIVE, "peak_torque": 2.0,
                                    "no_load_speed": 100.0})
    assert measured_torque(parameters, speed, command) == pytest.approx(expected)


def one_axis_config(folder, effects: str):
    """A bus config of the one axis (1 kHz plant, 500 Hz bus 'axis' on virtual channel
    'one-axis-effects'), its drive's ``effects`` on line 9."""
    path = folder / "one_axis.yaml"
    path.write_text(
        f"robot: {ONE_AXIS}\nplant_rate_hz: 1000\nbuses:\n  - name: axis\n"
        "    interface: virtual\n    channel: one-axis-effects\n    cycle_hz: 500\n"
        f"    drives:\n      - {{node_id: 1, joint: yaw, effects: {{{effects}}}}}\n")
    return path


def test_the_simulator_and_hil_check_take_a_bus_configs_effects(tmp_path, capsys):
    config_path = one_axis_config(tmp_path, "coulomb_friction: 0.02, viscous_friction: 0.01, "
                                            "delay: 0.002, no_load_speed: 400")
    config = load_bus_config(config_path)
    buses = {"axis": can.Bus(interface="virtual", channel="one-axis-effects")}
    simulator = Simulator(config, buses)
    try:
        model = simulator.plant.model
        motor = model.actuator("yaw_motor")
        assert model.actuator_damping[motor.id] == 0.01
        assert model.actuator_delay[motor.id] == pytest.approx(0.002)
        assert model.dof_frictionloss[model.joint("yaw").dofadr[0]] == pytest.approx(0.2)
        assert simulator.drives[0].core.parameters.no_load_speed == 400
    finally:
        simulator.close()
        buses["axis"].shutdown()
    assert main(["check", str(config_path)]) == 0
    assert ("node 1 (yaw): coulomb_friction 0.02, viscous_friction 0.01, delay 0.002, "
            "no_load_speed 400") in capsys.readouterr().out


def test_a_delay_between_plant_steps_is_rounded_and_said_so(tmp_path):
    config = load_bus_config(one_axis_config(tmp_path, "delay: 0.0024"))
    (warning,) = [w for w in config.warnings if "delay" in w.message]
    assert "0.0024 s is not a whole number of plant steps (0.001 s): the plant delays it 2 " \
           "step(s)" in warning.message and warning.line == 9
    plant = Plant(config.robot, timestep=0.001, effects=config.effects)
    assert plant.model.actuator_delay[0] == pytest.approx(0.002)



def held_motor_under_load(plant: Plant, load, steps: int) -> list[float]:
    """The disc's angle from the start, its motor held still (an inertia of 1e6 kg m^2 on the
    motor side's hinge: a motor that does not give), under an outside torque ``load(step)``
    (N·m) on the disc about its axis."""
    model, data = plant.model, plant.data
    model.dof_armature[model.joint("yaw").dofadr[0]] = 1e6
    disc = model.body("disc").id
    start = float(plant.joint_positions()[0])
    angles = []
    for step in range(steps):
        data.xfrc_applied[disc, 5] = load(step)             # about the vertical axis
        plant.step()
        angles.append(float(plant.joint_positions()[0]) - start)
    return angles


@pytest.mark.parametrize("width", [0.01, 0.002])
def test_backlash_is_lost_motion_of_exactly_its_width_on_reversal(one_axis, width):
    forward = held_motor_under_load(plant_with(one_axis, backlash=width), lambda _: 0.1, 800)
    back = held_motor_under_load(plant_with(one_axis, backlash=width), lambda _: -0.1, 800)
    # the band's ends give as a tooth contact does: about 4 urad under 0.1 N·m
    assert forward[-1] - back[-1] == pytest.approx(width, abs=1e-5)     # end to end
    assert forward[-1] == pytest.approx(width / 2, abs=5e-6)            # from the middle


def test_gear_stiffness_deflects_the_output_by_load_over_stiffness(one_axis):
    deflection = held_motor_under_load(plant_with(one_axis, gear_stiffness=50.0,
                                                  gear_damping=2.0), lambda _: 0.5, 3000)
    assert deflection[-1] == pytest.approx(0.5 / 50.0, rel=1e-3)        # tau / k


def test_gear_damping_decays_the_outputs_ringing_at_its_damping_ratio(one_axis):
    """Released from a static load, the disc rings on the gear's spring: period and
    logarithmic decrement those of k, d and the disc's 0.02 kg m^2 (zeta = d / 2 sqrt(k I))."""
    k, d, inertia = 50.0, 0.1, 0.02
    angle = held_motor_under_load(plant_with(one_axis, gear_stiffness=k, gear_damping=d),
                                  lambda step: 0.5 if step < 2000 else 0.0, 4000)[2000:]
    peaks = [i for i in range(1, len(angle) - 1)
             if angle[i - 1] < angle[i] >= angle[i + 1] and angle[i] > 0]
    decrement = math.log(angle[peaks[0]] / angle[peaks[1]])
    zeta = d / (2 * math.sqrt(k * inertia))
    assert decrement / math.sqrt(4 * math.pi ** 2 + decrement ** 2) == pytest.approx(zeta,
                                                                                   rel=0.02)
    period = (peaks[1] - peaks[0]) * STEP
    assert period == pytest.approx(2 * math.pi / (math.sqrt(k / inertia)
                                                  * math.sqrt(1 - zeta ** 2)), abs=STEP)


def test_gear_effects_need_one_joint_and_one_kind(tmp_path, coupled):
    with pytest.raises(HilError, match="backlash and gear_stiffness/gear_damping together"):
        load_bus_config(one_axis_config(tmp_path, "backlash: 0.01, gear_stiffness: 100"))
    with pytest.raises(HilError, match="gear_damping without gear_stiffness"):
        load_bus_config(one_axis_config(tmp_path, "gear_damping: 1"))


def test_the_encoder_quantises_position_to_its_counts():
    core = DriveCore(DriveParameters(**{**TEST_MOTOR_DRIVE, "counts_per_rev": 4096}))
    count = 2 * math.pi / 4096
    for position, counts in ((0.4 * count, 0), (0.6 * count, 1), (-1000.4 * count, -1000)):
        core.measure(position, 0.0)
        assert core.status().position == pytest.approx(counts * count)


def test_a_velocity_filter_estimates_speed_from_counts_through_its_time_constant():
    """At a constant 3 rad/s the drive reads counts; the first-order filter (T = 5 ms) rises
    as 1 - (T / (T + dt))^n and holds the speed within the quantisation of a count."""
    counts, dt, speed, constant = 4096, 0.001, 3.0, 0.005
    core = DriveCore(DriveParameters(**{**TEST_MOTOR_DRIVE, "counts_per_rev": counts,
                                        "velocity_filter": constant}))
    core.measure(0.0, 0.0)
    estimates = []
    for step in range(1, 200):
        core.measure(speed * step * dt, -99.0, dt)             # the given velocity is unused
        estimates.append(core.status().velocity)
    quantum = 2 * math.pi / counts / dt                          # one count in one step
    pole = constant / (constant + dt)
    for n in (1, 5, 25):
        assert estimates[n - 1] == pytest.approx(speed * (1 - pole ** n), abs=quantum)
    assert sum(estimates[100:]) / len(estimates[100:]) == pytest.approx(speed, rel=0.01)
    assert max(abs(v - speed) for v in estimates[100:]) < quantum
