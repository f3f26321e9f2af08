"""Property-based: any controllers file a bus config names (issue 65: the property suite
covers controllers files as it covers bus configs) is either loaded or refused with a
HilError naming what to change, never another exception; and nothing ``hil check`` takes
makes ``hil control`` fail at start, where it builds its controller manager from the file's
controllers (:meth:`ControllerManager.from_config`, as :class:`ControlNode` does).

The files are the real layouts hil reads (tests/controllers: Universal Robots' own
ur_controllers.yaml, ros2_control_demos' rrbot_jtc.yaml) and a file of the layouts they lack
(``/**:`` sections, a forward controller with its own type and interface_name), changed key
by key: wrong types at every key, keys removed, unknown keys, huge and deep values, YAML
anchors and aliases, launch substitutions and unicode."""

from __future__ import annotations

import copy
import os
from pathlib import Path

import pytest
import yaml
import zenoh
from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from hil.bus_config import load_bus_config
from hil.control_node.node import ControlNode
from hil.controllers import config as config_module
from hil.controllers.config import MAX_REFUSED_SUBSTITUTIONS, controllers_for
from hil.errors import HilError
from hil.hardware.interface import FakeHardwareInterface
from hil.realtime import LOCK_STEP

HERE = Path(__file__).parent
#: examples per property: 80 in CI, each a file read and a manager built (HIL_PROPERTY_EXAMPLES
#: for a longer search)
BOUNDED = settings(max_examples=int(os.environ.get("HIL_PROPERTY_EXAMPLES", "80")),
                   deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                         HealthCheck.too_slow,
                                                         HealthCheck.data_too_large])
#: the ur3 fixture's bench (driven joints joint1..joint6), robot by absolute path
BENCH = (HERE / "fixtures" / "ur3_virtual.yaml").read_text().replace(
    "../../robots", str(HERE.parent / "robots"))
UR_NAMES = {"shoulder_pan_joint": "joint1", "shoulder_lift_joint": "joint2",
            "elbow_joint": "joint3", "wrist_1_joint": "joint4", "wrist_2_joint": "joint5",
            "wrist_3_joint": "joint6"}
#: the layouts hil reads, each with the bus config's ``controllers:`` entry that runs it
MIXED = """\
/**:
  ros__parameters:
    command_interfaces: [position, velocity]
    state_interfaces: [position, velocity]
controller_manager:
  ros__parameters:
    update_rate: 100
    jtc: {type: joint_trajectory_controller/JointTrajectoryController}
    fwd_position: {type: position_controllers/JointGroupPositionController}
jtc:
  ros__parameters:
    joints: [joint1, joint2, joint3]
    allow_partial_joints_goal: true
    allow_nonzero_velocity_at_trajectory_end: false
    allow_integration_in_goal_trajectories: true
    interpolation_method: splines
    action_monitor_rate: 20.0
    cmd_timeout: 0.0
    gains: {joint1: {p: 1.0}}
    speed_scaling: {initial_scaling_factor: 1.0}
    constraints:
      stopped_velocity_tolerance: 0.01
      goal_time: 0.5
      decelerate_on_cancel: false
      joint1: {trajectory: 0.2, goal: 0.1, max_deceleration_on_cancel: 1.0}
      joint2: {goal: 0.05}
fwd_position:
  ros__parameters:
    joints: [joint4, joint5]
fwd_velocity:
  ros__parameters:
    type: forward_command_controller/ForwardCommandController
    joints: [joint6]
    interface_name: velocity
"""
LAYOUTS = [
    ((HERE / "controllers" / "ur_controllers.yaml").read_text(),
     {"joint_names": UR_NAMES, "vars": {"tf_prefix": ""},
      "active": ["joint_trajectory_controller"]}),
    ((HERE / "controllers" / "rrbot_jtc.yaml").read_text(), {}),
    (MIXED, {"active": ["jtc", "fwd_velocity"]}),
]
#: values of every kind a hand-edited file holds, and the odd ones: huge, deep, long,
#: substitutions, unicode
SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=12),
    st.sampled_from([10 ** 400, -(10 ** 400), 1e308, 5e-324, -1.0, 0, "joint1", "joint7",
                     "position", "velocity", "effort", "splines", "$(var tf_prefix)joint1",
                     "$(var nope)", "$(command ls)", "$(find-pkg-share x)", "$(env HOME)",
                     "$(", "é\u202ejoint1", "\U0001F916", "x" * 5000, "joint_trajectory_"
                     "controller/JointTrajectoryController", "position_controllers/"
                     "JointGroupPositionController", "ros__parameters", "/**", "type"]))
VALUES = st.one_of(
    st.recursive(SCALARS, lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(st.one_of(st.text(max_size=8), st.sampled_from(
            ["ros__parameters", "type", "joints", "goal", "trajectory", "joint1"])),
            inner, max_size=4)), max_leaves=10),
    st.integers(1, 400).map(lambda depth: _deep(depth)),
    st.integers(1, 3000).map(lambda n: [f"joint{i % 7}" for i in range(n)]))


#: the parameters the controllers declare (joint_trajectory_controller_parameters.yaml,
#: forward_command_controller's), each a place for a value in a controller's section
PARAMETERS = ["type", "joints", "command_joints", "command_interfaces", "state_interfaces",
              "allow_partial_joints_goal", "allow_nonzero_velocity_at_trajectory_end",
              "interpolate_from_desired_state", "allow_integration_in_goal_trajectories",
              "reject_unreachable_first_point", "open_loop_control", "action_monitor_rate",
              "cmd_timeout", "interpolation_method",
              "set_last_command_interface_value_as_state_on_activation", "gains",
              "speed_scaling", "constraints", "interface_name", "update_rate"]
CONSTRAINTS = ["stopped_velocity_tolerance", "goal_time", "decelerate_on_cancel", "joint1",
               "shoulder_pan_joint"]
JOINTS = st.lists(st.sampled_from([f"joint{i}" for i in range(1, 7)]), min_size=1, max_size=6,
                  unique=True)
#: values a controller takes at each key, that a file may still combine wrongly
PLAUSIBLE = {"joints": JOINTS, "command_joints": JOINTS,
             "command_interfaces": st.sampled_from([["position"], ["position", "velocity"]]),
             "state_interfaces": st.sampled_from([["position"], ["position", "velocity"]]),
             "interface_name": st.sampled_from(["position", "velocity"]),
             "type": st.sampled_from(["joint_trajectory_controller/JointTrajectoryController",
                                      "position_controllers/JointGroupPositionController",
                                      "velocity_controllers/JointGroupVelocityController",
                                      "forward_command_controller/ForwardCommandController"])}
NUMBERS = st.one_of(st.floats(), st.integers(), st.floats(0, 1e-300),
                    st.sampled_from([5e-324, 1e-308, 0.05, 0.1, 1e308, 10 ** 400]))


def _deep(depth: int):
    value: object = "joint1"
    for level in range(depth):
        value = [value] if level % 2 else {"ros__parameters": value}
    return value


def _places(node, path=()):
    """Every key path of a loaded document, lists' items included, to the depth of the
    layouts (not into a deep value a change put there)."""
    yield path
    if len(path) >= 8:
        return
    items = node.items() if isinstance(node, dict) else \
        enumerate(node) if isinstance(node, list) else ()
    for key, value in items:
        yield from _places(value, (*path, key))


def _parent_of(document, path):
    """The mapping or list that holds the value at ``path``."""
    for key in path[:-1]:
        document = document[key]
    return document


@st.composite
def changes(draw, document):
    """``document`` changed at a few places: a value set, a key removed, an unknown key
    added, or a value made an alias of another's (PyYAML writes it with an anchor)."""
    document = copy.deepcopy(document)
    for _ in range(draw(st.integers(1, 3))):
        places = [p for p in _places(document) if p]
        if not places:
            break
        path = draw(st.sampled_from(places))
        parent = _parent_of(document, path)
        action = draw(st.sampled_from(["set", "set", "remove", "add", "alias", "parameter"]))
        sections = [p for p in places if p[-1] == "ros__parameters"
                    and isinstance(_parent_of(document, p)[p[-1]], dict)]
        if action == "parameter" and sections:
            params = _parent_of(document, draw(st.sampled_from(sections)))["ros__parameters"]
            key = draw(st.sampled_from(PARAMETERS))
            value = draw(st.one_of(PLAUSIBLE.get(key, st.booleans()), NUMBERS, VALUES))
            if key == "constraints" and draw(st.booleans()):
                value = {draw(st.sampled_from(CONSTRAINTS)): draw(st.one_of(
                    NUMBERS, st.fixed_dictionaries({"goal": NUMBERS, "trajectory": NUMBERS})))}
            params[key] = value
        elif action == "set":
            parent[path[-1]] = draw(VALUES)
        elif action == "remove":
            del parent[path[-1]]
        elif action == "add" and isinstance(parent, dict):
            parent[draw(st.one_of(st.text(max_size=10), st.integers()))] = draw(VALUES)
        elif action == "alias":
            other = document
            for key in draw(st.sampled_from(places))[:-1]:
                other = other[key]
            if other is not parent:     # an ancestor makes a recursive alias: refused
                parent[path[-1]] = other
    return document


@st.composite
def controllers_files(draw):
    """A controllers file's text and the bus config's ``controllers:`` entry that names it."""
    text, entry = draw(st.sampled_from(LAYOUTS))
    entry = dict(entry)
    if draw(st.booleans()):
        document = draw(changes(yaml.safe_load(text)))
        text = yaml.safe_dump(document, sort_keys=False, allow_unicode=draw(st.booleans()),
                              width=10_000)
    if draw(st.integers(0, 4)) == 0:
        entry[draw(st.sampled_from(["joint_names", "vars", "active", "file"]))] = draw(VALUES)
    return text, entry


@pytest.fixture
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("controllers")


@pytest.fixture(scope="module")
def session():
    """A Zenoh session that reaches nobody (no scouting, no endpoints): the control node's
    faces declare on it and hear nothing."""
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", "[]")
    with zenoh.open(config) as opened:
        yield opened


def _bench(folder: Path, text: str, entry: dict) -> Path:
    (folder / "controllers.yaml").write_text(text, encoding="utf-8")
    bench = folder / "bench.yaml"
    bench.write_text(BENCH + "controllers: " + yaml.safe_dump(
        {"file": "controllers.yaml", **entry}, default_flow_style=True, width=10_000))
    return bench


def _started(bench: Path, session: zenoh.Session) -> bool:
    """What ``hil check`` reads of ``bench`` (HilError where it refuses it), and, where it
    takes it, the control node ``hil control`` makes of it at start (its controller manager,
    feedback and joint-state rates, faces), over hardware with the robot's driven joints as
    CanHardwareInterface has them, no bus opened and no cycle run."""
    try:
        config = load_bus_config(bench)
        controllers = controllers_for(config)
    except HilError:
        return False
    node = ControlNode(FakeHardwareInterface(config.robot), session, config.cycle_hz,
                       LOCK_STEP, controllers=controllers)
    for face in node.faces:
        face.close()
    assert node.controller.name == controllers.trajectory_name
    return True


@BOUNDED
@given(controllers_files())
@example((LAYOUTS[1][0].replace("action_monitor_rate: 20.0", "action_monitor_rate: 5.0e-324"),
          {}))                      # once an OverflowError at hil control's start
def test_any_controllers_file_is_refused_or_starts_the_control_node(folder, session, file):
    event("started" if _started(_bench(folder, *file), session) else "refused")


_INTERFACES = ", command_interfaces: [position], state_interfaces: [position]"
ODD_YAML = [
    # anchors, aliases and a merge key over a controller's section
    "controller_manager:\n  ros__parameters:\n    jtc: {type: joint_trajectory_controller/"
    "JointTrajectoryController}\nbase: &base\n  ros__parameters:\n    joints: &j [joint1]\n"
    "jtc:\n  <<: *base\n  ros__parameters:\n    <<: {joints: *j}\n"
    "    command_interfaces: [position]\n    state_interfaces: [position]\n",
    # a recursive alias
    "jtc: &a\n  ros__parameters:\n    type: joint_trajectory_controller/"
    "JointTrajectoryController\n    joints: [joint1]\n    constraints: {joint1: *a}\n",
    # an alias bomb
    "a: &a [x, x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
    "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c]\n"
    "e: [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]\n",
    # tags: a Python object (the safe loader refuses it), binary, a set, an ordered map
    "jtc: !!python/object/apply:os.system [ls]\n",
    "jtc:\n  ros__parameters:\n    type: !!binary aGVsbG8=\n    joints: !!set {joint1}\n",
    "jtc:\n  ros__parameters: !!omap [{type: joint_trajectory_controller/"
    "JointTrajectoryController}, {joints: [joint1]" + _INTERFACES + "}]\n",
    # a complex key, a null key, a key that is a number, duplicate keys
    "? [a, b]\n: {ros__parameters: {}}\n",
    "~: {ros__parameters: {type: joint_trajectory_controller/JointTrajectoryController,"
    " joints: [joint1]" + _INTERFACES + "}}\n",
    "1: {ros__parameters: {type: joint_trajectory_controller/JointTrajectoryController,"
    " joints: [joint1]" + _INTERFACES + "}}\n",
    "jtc: {ros__parameters: {type: joint_trajectory_controller/JointTrajectoryController,"
    " joints: [joint1]" + _INTERFACES + ", joints: [joint2],"
    " constraints: {1: {goal: 1}, ~: 2}}}\n",
    # several documents, none, a byte-order mark, tabs
    "---\njtc: {}\n---\nfwd: {}\n", "", "\ufeffjtc: {ros__parameters: {}}\n",
    "jtc:\n\tros__parameters: {}\n",
    # a wildcard alone, a namespaced and a nested section, an empty ros__parameters
    "/**:\n  ros__parameters:\n    type: joint_trajectory_controller/JointTrajectoryController\n"
    "    joints: [joint1]\n    command_interfaces: [position]\n    state_interfaces: [position]\n",
    "/rrbot/jtc:\n  ros__parameters:\n    type: joint_trajectory_controller/"
    "JointTrajectoryController\n    joints: [joint1]\n    command_interfaces: [position]\n"
    "    state_interfaces: [position]\nrrbot:\n  jtc:\n    ros__parameters:\n",
    "/*/**:\n  ros__parameters:\n    type: joint_trajectory_controller/JointTrajectoryController\n"
    "/:\n  ros__parameters: {joints: [joint1]" + _INTERFACES + "}\n",
]


@BOUNDED
@given(st.sampled_from(ODD_YAML), st.sampled_from([{}, {"active": ["jtc"]},
                                                   {"vars": {"x": "y"}}]))
def test_any_odd_yaml_as_a_controllers_file_is_refused_or_starts(folder, session, text,
                                                                 entry):
    event("started" if _started(_bench(folder, text, entry), session) else "refused")


# --- what the properties found, pinned ----------------------------------------------------------

RRBOT_JTC = LAYOUTS[1][0]


def test_an_action_monitor_rate_under_the_jtcs_least_is_refused_naming_the_line(folder,
                                                                                 session):
    """The JTC validates action_monitor_rate `gt_eq: [0.1]` (ros2_controllers jazzy,
    joint_trajectory_controller_parameters.yaml); hil check took any rate > 0, and a rate of
    5e-324 Hz made hil control fail at start (the feedback period, cycle_hz / rate, is no
    number of cycles: OverflowError)."""
    text = RRBOT_JTC.replace("action_monitor_rate: 20.0", "action_monitor_rate: 5.0e-324")
    with pytest.raises(HilError) as caught:
        controllers_for(load_bus_config(_bench(folder, text, {})))
    assert (f"{folder / 'controllers.yaml'}:15: error: controller "
            "'joint_trajectory_position_controller': action_monitor_rate must be >= 0.1, "
            "not 4.94066e-324") in str(caught.value), str(caught.value)
    assert _started(_bench(folder, text.replace("5.0e-324", "0.1"), {}), session)


@pytest.mark.parametrize("count", [20_000, 40_000])
def test_distinct_substitutions_are_reported_up_to_a_bound_each_line_found_once(
        folder, monkeypatch, count):
    """Issue 65 item 10: each distinct `$(...)` substitution was reported with its line, found
    by counting the newlines before it: work quadratic in the file (100k took 30 s, and the
    16 MB a file may hold allow about a million), a report of megabytes. Now the first
    MAX_REFUSED_SUBSTITUTIONS are reported, one error counts the rest, and a line is found
    only for those: as many line searches for 40k substitutions as for 20k."""
    searches = []
    monkeypatch.setattr(config_module, "_line_at", lambda text, index: searches.append(
        index) or text.count("\n", 0, index) + 1, raising=False)
    text = "jtc:\n  ros__parameters:\n    tf: [\n" + "".join(
        f"      $(command x{i}),\n" for i in range(count)) + "    ]\n"
    with pytest.raises(HilError) as caught:
        controllers_for(load_bus_config(_bench(folder, text, {})))
    shown = MAX_REFUSED_SUBSTITUTIONS
    assert len(caught.value.diagnostics) == shown + 1
    assert len(searches) == shown + 1
    assert str(caught.value.diagnostics[0]).startswith(
        f"{folder / 'controllers.yaml'}:4: error: launch substitution '$(command x0)'")
    assert str(caught.value.diagnostics[-1]).startswith(
        f"{folder / 'controllers.yaml'}:{4 + shown}: error: {count - shown} more launch "
        "substitutions hil cannot substitute")


def test_a_section_that_names_no_node_gives_no_controller(folder):
    """A section keyed `/` resolves to an empty node name, which no node has (rmw's
    rmw_validate_node_name refuses an empty name: RMW_NODE_NAME_INVALID_IS_EMPTY_STRING);
    hil took it for a controller named '' and ran it. Its parameters go to no node: a
    warning naming the line."""
    with pytest.raises(HilError) as caught:
        controllers_for(load_bus_config(_bench(folder, ODD_YAML[-1], {})))
    said = str(caught.value)
    assert f"{folder / 'controllers.yaml'}:4: warning: '/' names no node" in said, said
    assert "error: no controllers" in said, said
