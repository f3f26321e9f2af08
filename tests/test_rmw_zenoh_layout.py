"""hil's ROS 2 face against rmw_zenoh's documented layout (ros2/rmw_zenoh docs/design.md
and its liveliness_utils / qos / attachment sources), with the design document's own
examples and type hashes published for ROS 2 as vectors."""

from __future__ import annotations

import struct

import pytest
import xxhash

from hil.messaging import cdr
from hil.messaging.ros.interfaces import FollowJointTrajectory, TypeHashes, dds_type_name
from hil.messaging.ros.rmw_zenoh import (
    ACTION_STATUS_QOS, CLOCK_QOS, Attachment, Durability, Entity, EntityKind, QoS, Reliability,
    TopicInfo, liveliness_query, topic_keyexpr,
)

STRING = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_TWO_INTS = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
JOINT_STATE_JAZZY = "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"


@pytest.fixture(scope="module")
def jazzy():
    return TypeHashes("jazzy")


# --- key expressions (design.md, "Topic and Service name mapping") ----------------------

@pytest.mark.parametrize("domain, name, type_name, type_hash, expected", [
    (0, "/chatter", "std_msgs::msg::dds_::String_", STRING,
     f"0/chatter/std_msgs::msg::dds_::String_/{STRING}"),
    (0, "/robot1/chatter", "std_msgs::msg::dds_::String_", STRING,
     f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING}"),
    (2, "/add_two_ints", "example_interfaces::srv::dds_::AddTwoInts_", ADD_TWO_INTS,
     f"2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS}"),
])
def test_topic_and_service_keys_are_the_design_documents_examples(domain, name, type_name,
                                                                 type_hash, expected):
    assert topic_keyexpr(domain, name, type_name, type_hash) == expected


def test_type_names_take_the_dds_form():
    assert dds_type_name("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert (dds_type_name("control_msgs/action/FollowJointTrajectory_SendGoal")
            == "control_msgs::action::dds_::FollowJointTrajectory_SendGoal_")


# --- liveliness tokens (design.md, "Graph Cache") ---------------------------------------

def _entity(kind, session, node_name, entity_id=10, topic=None, domain=2):
    return Entity(domain, session, 0, entity_id, kind, "/", node_name, "", topic)


@pytest.mark.parametrize("entity, token", [
    (_entity(EntityKind.NODE, "aac3178e146ba6f1fc6e6a4085e77f21", "listener", entity_id=0),
     "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"),
    (_entity(EntityKind.SUBSCRIPTION, "aac3178e146ba6f1fc6e6a4085e77f21", "listener",
             topic=TopicInfo("/chatter", "std_msgs::msg::dds_::String_", STRING, QoS(depth=10))),
     "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
     f"std_msgs::msg::dds_::String_/{STRING}/::,10:,:,:,,"),
    (_entity(EntityKind.PUBLISHER, "8b20917502ee955ac4476e0266340d5c", "talker",
             topic=TopicInfo("/chatter", "std_msgs::msg::dds_::String_", STRING, QoS(depth=7))),
     "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
     f"std_msgs::msg::dds_::String_/{STRING}/::,7:,:,:,,"),
    (_entity(EntityKind.SERVICE, "f9980ee0495eaafb3e38f0d19e2eae12", "add_two_ints_server",
             topic=TopicInfo("/add_two_ints", "example_interfaces::srv::dds_::AddTwoInts_",
                             ADD_TWO_INTS, QoS(depth=10))),
     "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/"
     f"%add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS}/::,10:,:,:,,"),
    (_entity(EntityKind.CLIENT, "e1dc8d1b45ae8717fce78689cc655685", "add_two_ints_client",
             topic=TopicInfo("/add_two_ints", "example_interfaces::srv::dds_::AddTwoInts_",
                             ADD_TWO_INTS, QoS(depth=10))),
     "@ros2_lv/2/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/"
     f"%add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS}/::,10:,:,:,,"),
])
def test_liveliness_tokens_are_the_design_documents_examples(entity, token):
    assert entity.token() == token
    assert Entity.from_token(token) == entity


def test_a_namespace_is_mangled_in_the_token_and_kept_in_the_topic_key():
    entity = Entity(0, "ab", 0, 3, EntityKind.PUBLISHER, "/robot1", "hil_control", "",
                    TopicInfo("/robot1/joint_states", "sensor_msgs::msg::dds_::JointState_",
                              JOINT_STATE_JAZZY, QoS(depth=10)))
    assert entity.token().split("/")[7:10] == ["%robot1", "hil_control", "%robot1%joint_states"]
    assert entity.keyexpr().startswith("0/robot1/joint_states/sensor_msgs::msg::dds_::")


@pytest.mark.parametrize("token", [
    "@ros2_lv/0/ab/0/0/XX/%/%/node",                     # unknown entity kind
    "@ros2_lv/0/ab/0/0/NN/%/%",                          # too few parts
    "@ros2_lv/0/ab/0/1/MP/%/%/node",                     # a publisher without its topic
    "other/0/ab/0/0/NN/%/%/node",                        # not the admin space
    "@ros2_lv/0/ab/0/1/MP/%/%/node/%t/T_/RIHS01_x/::,10",  # a malformed QoS
])
def test_malformed_tokens_are_refused_with_the_reason(token):
    with pytest.raises(ValueError):
        Entity.from_token(token)


def test_the_graph_query_covers_one_domain():
    assert liveliness_query(7) == "@ros2_lv/7/**"


# --- QoS (liveliness_utils qos_to_keyexpr, qos.cpp defaults) ----------------------------

@pytest.mark.parametrize("qos, text", [
    (QoS(), "::,:,:,:,,"),                                   # rmw_zenoh's defaults: all empty
    (QoS(depth=10), "::,10:,:,:,,"),
    (ACTION_STATUS_QOS, ":1:,1:,:,:,,"),                     # transient local, depth 1
    (CLOCK_QOS, "2::,1:,:,:,,"),                             # best effort, depth 1
    (QoS(Reliability.BEST_EFFORT, Durability.TRANSIENT_LOCAL, depth=5), "2:1:,5:,:,:,,"),
])
def test_qos_is_encoded_as_rmw_zenoh_encodes_it(qos, text):
    assert qos.to_keyexpr() == text
    assert QoS.from_keyexpr(text) == qos


# --- the attachment (design.md, "Publishers" / "Service Clients") -----------------------

def test_the_attachment_is_33_bytes_little_endian():
    gid = bytes(range(16))
    packed = Attachment(sequence_number=258, source_timestamp=1_700_000_000_123_456_789,
                        gid=gid).pack()
    assert len(packed) == 33
    assert packed[:8] == (258).to_bytes(8, "little")
    assert packed[8:16] == (1_700_000_000_123_456_789).to_bytes(8, "little")
    assert packed[16] == 16 and packed[17:] == gid
    assert Attachment.unpack(packed) == Attachment(258, 1_700_000_000_123_456_789, gid)


@pytest.mark.parametrize("data", [None, b"", bytes(32), bytes(16) + b"\x0f" + bytes(16)])
def test_malformed_attachments_are_refused(data):
    with pytest.raises(ValueError):
        Attachment.unpack(data)


def test_the_gid_is_xxh3_128_of_the_token_low_half_first():
    entity = _entity(EntityKind.PUBLISHER, "8b20917502ee955ac4476e0266340d5c", "talker",
                     topic=TopicInfo("/chatter", "std_msgs::msg::dds_::String_", STRING))
    canonical = xxhash.xxh3_128_digest(entity.token().encode())   # big endian: high, low
    high, low = struct.unpack(">QQ", canonical)
    assert entity.gid() == struct.pack("<QQ", low, high)


# --- payloads: CDR with the 4-byte encapsulation header ---------------------------------

def test_payloads_carry_the_cdr_little_endian_encapsulation_header():
    payload = cdr.encode(cdr.joint_state_msg(0.0, ["a"], [1.0], [0.0], [0.0]))
    assert payload[:4] == b"\x00\x01\x00\x00"
    assert cdr.EMPTY_REQUEST[:4] == b"\x00\x01\x00\x00"


# --- type hashes (REP-2016) against values ROS 2 publishes -------------------------------

def test_message_hashes_are_the_published_jazzy_ones(jazzy):
    assert jazzy.rihs01("sensor_msgs/msg/JointState") == JOINT_STATE_JAZZY
    assert jazzy.rihs01("std_msgs/msg/String") == STRING


def test_a_service_hash_covers_request_response_and_event(jazzy):
    jazzy.define("example_interfaces/srv/AddTwoInts_Request", "int64 a\nint64 b")
    jazzy.define("example_interfaces/srv/AddTwoInts_Response", "int64 sum")
    assert jazzy.service("example_interfaces/srv/AddTwoInts").type_hash == ADD_TWO_INTS


def test_action_service_hashes_are_the_published_fibonacci_ones(jazzy):
    """example_interfaces/action/Fibonacci's send_goal and get_result hashes as rosidl
    generates them for Jazzy (the service types under the action)."""
    base = "example_interfaces/action/Fibonacci"
    jazzy.define(f"{base}_Goal", "int32 order")
    jazzy.define(f"{base}_Result", "int32[] sequence")
    jazzy.define(f"{base}_SendGoal_Request",
                 f"unique_identifier_msgs/msg/UUID goal_id\n{base}_Goal goal")
    jazzy.define(f"{base}_SendGoal_Response", "bool accepted\nbuiltin_interfaces/msg/Time stamp")
    jazzy.define(f"{base}_GetResult_Request", "unique_identifier_msgs/msg/UUID goal_id")
    jazzy.define(f"{base}_GetResult_Response", f"int8 status\n{base}_Result result")
    assert jazzy.service(f"{base}_SendGoal").type_hash == (
        "RIHS01_d1a57fb2a4afe8c21e34fb10db206f16ce6729b28531141472df92277c55b557")
    assert jazzy.service(f"{base}_GetResult").type_hash == (
        "RIHS01_1b0de0d5d29dc955d92f546706568428632771db13ec84c15ec1c1a59f424a57")


def test_follow_joint_trajectory_endpoints_are_named_as_rcl_action_names_them(jazzy):
    action = FollowJointTrajectory.for_distro(jazzy)
    assert action.send_goal.type_name == (
        "control_msgs::action::dds_::FollowJointTrajectory_SendGoal_")
    assert action.get_result.type_name == (
        "control_msgs::action::dds_::FollowJointTrajectory_GetResult_")
    assert action.cancel_goal.type_name == "action_msgs::srv::dds_::CancelGoal_"
    assert action.feedback.type_name == (
        "control_msgs::action::dds_::FollowJointTrajectory_FeedbackMessage_")
    assert action.status.type_name == "action_msgs::msg::dds_::GoalStatusArray_"
    assert all(i.type_hash.startswith("RIHS01_") and len(i.type_hash) == 71
               for i in (action.send_goal, action.cancel_goal, action.get_result,
                         action.feedback, action.status))


def test_an_unknown_distribution_is_refused_with_the_known_ones():
    with pytest.raises(ValueError, match="jazzy"):
        TypeHashes("humble")
