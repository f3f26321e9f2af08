"""hil as ROS 2 nodes on rmw_zenoh, with no bridge (docs/ros2.md).

``rmw_zenoh``: the wire layout (keys, liveliness tokens, QoS, attachment, GID);
``interfaces``: type names and RIHS01 hashes; ``node``: contexts, nodes, publishers,
services, clients, subscriptions; ``action``: the FollowJointTrajectory server (an adapter
over hil's controller) and client; ``face``: the controller's and the simulator's nodes;
``router``: a Zenoh router with rmw_zenohd's settings.
"""
