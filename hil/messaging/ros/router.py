"""A Zenoh router with rmw_zenohd's settings (DEFAULT_RMW_ZENOH_ROUTER_CONFIG.json5), for
hosts without ROS 2: ROS nodes on rmw_zenoh and hil's ROS faces meet through it."""

from __future__ import annotations

import json

import zenoh

#: rmw_zenohd's listening endpoint: every interface, port 7447
DEFAULT_LISTEN = "tcp/[::]:7447"

#: the settings of rmw_zenohd's default router config that differ from Zenoh's defaults
RMW_ZENOHD_SETTINGS = {
    "mode": '"router"',
    "scouting/multicast/enabled": "false",      # ROS: discovery through the router only
    "scouting/gossip/enabled": "true",
    "scouting/gossip/target": '{router: ["router", "peer"], peer: ["router"]}',
    "scouting/gossip/autoconnect": '{router: [], peer: ["router", "peer"]}',
    "timestamping/enabled": '{router: true, peer: true, client: true}',
    "queries_default_timeout": "60000",
    "routing/router/peers_failover_brokering": "false",
}


def router_config(listen: tuple[str, ...] = (DEFAULT_LISTEN,)) -> zenoh.Config:
    """rmw_zenohd's router configuration, listening on ``listen``."""
    config = zenoh.Config()
    for key, value in RMW_ZENOHD_SETTINGS.items():
        config.insert_json5(key, value)
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return config


def open_router(listen: tuple[str, ...] = (DEFAULT_LISTEN,)) -> zenoh.Session:
    """Run a router in this process until the returned session is closed."""
    return zenoh.open(router_config(listen))


__all__ = ["DEFAULT_LISTEN", "RMW_ZENOHD_SETTINGS", "open_router", "router_config"]
