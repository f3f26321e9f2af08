"""Each actuator effect of a bus config (``effects:``) against its closed form, on one
vertical axis behind a 10:1 gear: MuJoCo's own models in the plant (Coulomb and viscous
friction, delay) and the drive's torque-speed line."""

from __future__ import annotations

import can
import pytest

from hil.bus_config import load_bus_config
from hil.bus_config.types import ActuatorEffects
from hil.cli import main
from hil.description import load_description
from hil.drives.core import DriveCore
from hil.drives.definitions import DriveParameters, Mode
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

