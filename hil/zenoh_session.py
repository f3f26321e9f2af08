"""How a hil process joins Zenoh: endpoints in, one shared session out.

Every process (sim, control, viz, clients) is a Zenoh peer. By default it
talks to loopback only: multicast scouting is off, and peers find each other
through explicit ``listen``/``connect`` endpoints (``tcp/127.0.0.1:PORT``).
For several hosts, give routable endpoints or a Zenoh config file.

Without endpoints, the hil processes of one host meet at one endpoint
(:func:`meeting_endpoint`, ``tcp/127.0.0.1:7450``): the first to start listens there, the
others connect to it, and Zenoh's gossip tells each about the others, so that every pair
ends up linked directly (each also listens on a loopback port of its own). Any order of
start works, and when the one listening there ends, the others keep dialling it until a
new process listens there. Peers, not a router: nothing relays another process' messages,
so a process' own access rules (``--secure``) see who sent each message it acts on.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
from dataclasses import dataclass, replace
from pathlib import Path

import zenoh

from hil.errors import HilError
from hil.input_files import read_input_file
from hil.zenoh_security import Identity, secured_endpoint

log = logging.getLogger(__name__)

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7450"     # 7447 is Zenoh's and ROS 2's router port
#: the environment variable that moves the meeting point (tests, two benches on one host)
MEETING_VARIABLE = "HIL_ZENOH_ENDPOINT"
LOOPBACK_ANY_PORT = "tcp/127.0.0.1:0"
#: how long a droppable put (a CAN frame) may wait for room in a congested link before it
#: is dropped (us; Zenoh's default is 1000): about one CAN frame's time at 1 Mbit/s, so a
#: drive answering under congestion holds its simulator's lock no longer than a CAN
#: controller would wait for the bus
DROP_WAIT_US = 150
#: TCP socket buffers of every link (bytes; Linux grows them to several MB by itself): what a
#: link holds in flight, about 2000 CAN frames each way. A sender faster than its receiver
#: then sees congestion and drops, as on a CAN bus, instead of queueing seconds of frames in
#: the kernel for the receiver to work through long after (a flood was still being
#: answered seconds after it ended: docs/performance.md,
#: "2026-12-06, later: figures from code comments")
SOCKET_BUFFER = 65536


#: what a name that becomes part of a key expression may not contain: Zenoh's wildcards
#: and reserved characters (a robot named ``**`` would address every robot)
_NOT_IN_NAMES = set("*$?#")


def key_name_problem(name: str, slashes: bool = False) -> str | None:
    """Why ``name`` cannot be a plain part of a Zenoh key expression (a robot's name; with
    ``slashes``, a CAN channel's, which may have several chunks), or None where it can."""
    if not name:
        return "it is empty"
    bad = sorted(set(name) & (_NOT_IN_NAMES | (set() if slashes else {"/"})))
    if bad:
        return f"it holds {' '.join(repr(c) for c in bad)}, which Zenoh reads as wildcards " \
               "or separators"
    try:
        zenoh.KeyExpr(f"hil/{name}")
    except zenoh.ZError as exc:
        return f"it is not a Zenoh key expression ({exc})"
    return None


def meeting_endpoint() -> str:
    """Where the hil processes of this host meet when given no endpoints: $HIL_ZENOH_ENDPOINT,
    else DEFAULT_ENDPOINT."""
    return os.environ.get(MEETING_VARIABLE) or DEFAULT_ENDPOINT


def free_loopback_port() -> int:
    """A TCP port on 127.0.0.1 that is free right now (for a Zenoh endpoint to listen on)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@dataclass(frozen=True)
class ZenohSettings:
    """Where this process listens and whom it connects to; or, with ``meet``, the endpoint
    where it listens if it is free and which it connects to if not (see the module doc)."""

    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    config_file: Path | None = None
    meet: str | None = None
    #: with one, TLS only, mutual, and the access policy (hil.zenoh_security)
    identity: Identity | None = None

    @classmethod
    def meeting(cls, identity: Identity | None = None) -> ZenohSettings:
        """The settings of a process given no endpoints: the host's meeting point."""
        return cls(meet=meeting_endpoint(), identity=identity)

    def hosting(self) -> ZenohSettings:
        """These settings, listening at the meeting point."""
        return replace(self, listen=self.listen + (self.meet,), meet=None)

    def joining(self) -> ZenohSettings:
        """These settings, connecting to the meeting point."""
        return replace(self, connect=self.connect + (self.meet,), meet=None)

    def to_config(self) -> zenoh.Config:
        try:
            config = _config_file(self.config_file) if self.config_file else zenoh.Config()
            if self.config_file is None:
                config.insert_json5("mode", '"peer"')
                config.insert_json5("scouting/multicast/enabled", "false")
                config.insert_json5(
                    "transport/link/tx/queue/congestion_control/drop/wait_before_drop",
                    str(DROP_WAIT_US))
                config.insert_json5("transport/link/tcp/so_sndbuf", str(SOCKET_BUFFER))
                config.insert_json5("transport/link/tcp/so_rcvbuf", str(SOCKET_BUFFER))
            # Zenoh's own default listener is tcp/[::]:0, every interface and IPv6 only
            # where IPv6 exists; a process that only connects listens on loopback instead.
            listen = self.listen or (() if self.config_file else (LOOPBACK_ANY_PORT,))
            connect = self.connect
            if self.identity is not None:
                listen, connect = (tuple(map(secured_endpoint, listen)),
                                   tuple(map(secured_endpoint, connect)))
                for path, value in self.identity.zenoh_json().items():
                    config.insert_json5(path, value)
            if listen:
                config.insert_json5("listen/endpoints", json.dumps(list(listen)))
            if connect:
                config.insert_json5("connect/endpoints", json.dumps(list(connect)))
        except zenoh.ZError as exc:
            raise HilError.single(f"invalid Zenoh configuration: {exc}", self.config_file,
                                  hint="check the endpoints (e.g. tcp/127.0.0.1:7447)") from None
        return config


#: the Zenoh config file's suffixes Zenoh reads as JSON5 (zenoh-config's Config::from_file:
#: .json and .json5; .yaml as YAML; any other it refuses)
_JSON5_SUFFIXES = (".json", ".json5")


def _config_file(path: Path) -> zenoh.Config:
    """The Zenoh config of ``path``, read through the bounded reader: Zenoh's own reader
    follows a FIFO or /dev/zero without end, and its parsers recurse (a JSON5 object
    nested 50,000 deep kills the process with SIGSEGV, measured with eclipse-zenoh 1.10)."""
    path = Path(path)
    syntax = "json" if path.suffix in _JSON5_SUFFIXES else "yaml"
    text = read_input_file(path, "Zenoh config", syntax=syntax,
                           hint="give a Zenoh JSON5 config file (e.g. zenoh.json5)")
    if syntax == "json":
        return zenoh.Config.from_json5(text)
    # Zenoh reads YAML by YAML 1.2 (serde_yaml), PyYAML by 1.1 (``on`` is a boolean there):
    # Zenoh reads the file itself, now that it is known to be a small, shallow regular file
    return zenoh.Config.from_file(str(path))


_sessions: dict[ZenohSettings, zenoh.Session] = {}
_lock = threading.Lock()


def session(settings: ZenohSettings) -> zenoh.Session:
    """The process' session for these settings (opened once, shared)."""
    with _lock:
        if settings not in _sessions:
            _sessions[settings] = _open(settings)
        return _sessions[settings]


def dials_peers(settings: ZenohSettings) -> bool:
    """Whether the process' session for these settings connects to someone (endpoints to
    connect to, or a meeting point another process holds): it has peers to wait for."""
    return bool(settings.connect) or settings in _joined


#: meeting settings whose session found the meeting point taken and connected to it
_joined: set[ZenohSettings] = set()


def _open(settings: ZenohSettings) -> zenoh.Session:
    if settings.meet is not None:
        try:     # the first at the meeting point listens there; the OS decides who is first
            return _zenoh_open(settings.hosting().to_config())
        except zenoh.ZError:
            _joined.add(settings)
            settings = settings.joining()
    try:
        return _zenoh_open(settings.to_config())
    except zenoh.ZError as exc:
        raise HilError.single(
            f"cannot open a Zenoh session (listen {list(settings.listen)}, connect "
            f"{list(settings.connect)}): {exc}",
            hint="is the listen port already taken by another hil process? "
                 "choose another with --listen") from None


#: the environment variable Zenoh reads its runtime's thread settings from
RUNTIME_VARIABLE = "ZENOH_RUNTIME"


def _zenoh_open(config: zenoh.Config) -> zenoh.Session:
    """``zenoh.open``; Zenoh's runtime failing to start (it panics in Rust: pyo3's
    PanicException, which derives from BaseException and has no importable name) raised as
    a HilError that names the cause a user can change."""
    try:
        return zenoh.open(config)
    except BaseException as exc:
        if type(exc).__name__ != "PanicException":
            raise
        runtime = os.environ.get(RUNTIME_VARIABLE)
        # Zenoh reads its runtime's settings from this variable as RON, and panics on any it
        # cannot parse (an empty one too)
        hint = (f"{RUNTIME_VARIABLE}={runtime!r} in the environment is not a Zenoh runtime "
                f"configuration (RON, e.g. '(rx: (worker_threads: 2))'): fix it, or unset it "
                "for Zenoh's defaults" if runtime is not None else None)
        raise HilError.single(f"Zenoh failed to start: {exc}", hint=hint) from None


def why_unreached(settings: ZenohSettings) -> str | None:
    """Why the process' session for these settings has no peer, in words, where it has none
    and dials someone (None otherwise): for each endpoint it dials, whether anything listens
    there (a plain TCP connect: Zenoh itself only retries), and so whether the far end
    refused this session (TLS on one side only, or keys of another CA)."""
    with _lock:
        opened = _sessions.get(settings)
    if opened is None or list(opened.info.peers_zid()):
        return None
    dialled = settings.connect + ((settings.meet,) if settings in _joined else ())
    words = []
    for endpoint in dialled:
        listening = _listening(endpoint)
        if listening is None:
            continue
        if not listening:
            words.append(f"nothing listens at {endpoint}")
        elif settings.identity is None:
            words.append(f"something listens at {endpoint} but made no Zenoh session with this "
                         "plain-TCP process: a process with --secure takes TLS only (give "
                         "--secure DIR here too)")
        else:
            words.append(f"something listens at {endpoint} but made no TLS session with this "
                         "--secure process: a process without --secure, or one with keys of "
                         "another CA")
    return "; ".join(words) or None


def _listening(endpoint: str) -> bool | None:
    """Whether a TCP connect to a tcp/tls endpoint's address succeeds (None: not such an
    endpoint)."""
    protocol, _, address = endpoint.partition("/")
    host, _, port = address.split("#")[0].rpartition(":")
    if protocol not in ("tcp", "tls") or not port.isdigit():
        return None
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=1.0):
            return True
    except OSError:
        return False


def close(settings: ZenohSettings) -> None:
    """Close the process' session for these settings, if one is open."""
    with _lock:
        opened = _sessions.pop(settings, None)
    if opened is not None:
        _closed(opened)


def close_all() -> None:
    """Close every session this process opened."""
    with _lock:
        for opened in _sessions.values():
            _closed(opened)
        _sessions.clear()


def _closed(opened: zenoh.Session) -> None:
    # Zenoh's close waits a bounded time for its tasks and raises ZError "close operation
    # timed out" past it (seen in `hil send` stopped by SIGINT on a loaded CI host): the
    # session is being let go either way, so a process ending keeps its own exit status
    # and says so in one line, not a traceback
    try:
        opened.close()
    except zenoh.ZError as exc:
        log.warning("the Zenoh session did not close in time: %s", exc)
