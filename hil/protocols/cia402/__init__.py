"""CANopen CiA 402 (CiA 301 communication): what drive and master share.

The simulated drive is :mod:`.drive` (over :mod:`.node`, the CiA 301 slave, and
:mod:`.state`, the 402 device without CAN); the master's side is :mod:`.axis`. Both read
their object dictionary from the EDS hil ships (:func:`hil.resources.eds_path`), and both
use python ``canopen`` on the bus' frame router (:mod:`.network`): canopen stays behind
this folder.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import FrameSource, Protocol, ProtocolOptions, Sender, SettingField

SYNC_ID = 0x080          # CiA 301's SYNC COB-ID
#: CiA 305 LSS: the master's requests, the slaves' answers, the node id of a drive that
#: boots without one
LSS_REQUEST_ID, LSS_ANSWER_ID, UNCONFIGURED = 0x7E5, 0x7E4, 255
NMT_ID = 0x000
TIME_ID = 0x100
#: CiA 301's predefined connection set: function code (the id's top 4 bits) -> the sender and
#: the frame's name; SYNC (0x080), NMT (0x000) and TIME (0x100) are the master's to all
FUNCTION_CODES = {0x080: (Sender.DRIVE, "EMCY"), 0x180: (Sender.DRIVE, "TPDO1"),
                  0x200: (Sender.MASTER, "RPDO1"), 0x280: (Sender.DRIVE, "TPDO2"),
                  0x300: (Sender.MASTER, "RPDO2"), 0x380: (Sender.DRIVE, "TPDO3"),
                  0x400: (Sender.MASTER, "RPDO3"), 0x480: (Sender.DRIVE, "TPDO4"),
                  0x500: (Sender.MASTER, "RPDO4"), 0x580: (Sender.DRIVE, "SDO answer"),
                  0x600: (Sender.MASTER, "SDO request"), 0x700: (Sender.DRIVE, "heartbeat")}

#: EMCY error codes of the drive's faults (CiA 301 table 21, CiA 402 for 0x86xx): a following
#: error, a position limit, the setpoints stopped (RPDO timeout), the master's heartbeat lost
#: (heartbeat consumer), an emergency stop (the drive's faults, as the core names them:
#: :data:`.errors.EMCY_CODES`)
EMCY_FOLLOWING_ERROR, EMCY_POSITION_LIMIT = 0x8611, 0x8612
EMCY_RPDO_TIMEOUT, EMCY_HEARTBEAT_LOST, EMCY_EMERGENCY_STOP = 0x8250, 0x8130, 0x9000
#: EMCY error codes a hil CiA 402 drive sends (CiA 301 / 402), for messages
EMCY_TEXT = {EMCY_FOLLOWING_ERROR: "following error",
             EMCY_POSITION_LIMIT: "position limit exceeded",
             EMCY_RPDO_TIMEOUT: "RPDO timeout (setpoints stopped arriving)",
             0x8210: "PDO too short (not processed)", 0x8220: "PDO longer than its mapping",
             0x8240: "unexpected SYNC length", EMCY_HEARTBEAT_LOST: "heartbeat/life guard error",
             EMCY_EMERGENCY_STOP: "emergency stop requested", 0x0000: "error reset"}
#: EMCY codes for a frame the drive ignored: the next cycle's frame replaces it
FRAME_ERRORS = frozenset({0x8210, 0x8220, 0x8240})
#: EMCY codes of a drive that lost its master's frames (its RPDO watchdog, its heartbeat
#: consumer): the errors of the master's silence
LINK_LOSS = frozenset({EMCY_RPDO_TIMEOUT, EMCY_HEARTBEAT_LOST})


def emcy_words(code: int) -> str:
    """An EMCY error code for messages: ``EMCY 0x8611 following error``."""
    return f"EMCY 0x{code:04X} {EMCY_TEXT.get(code, '')}".rstrip()


#: what a CiA 402 master may send beside each target position (``feed_forward`` option)
FEED_FORWARD = ("none", "velocity")


@dataclass(frozen=True)
class Cia402Options(ProtocolOptions):
    """A CiA 402 drive's settings in a bus config: ``feed_forward: velocity`` makes the
    master send the trajectory's velocity as the drive's velocity offset (0x60B1, RPDO4
    0x500+id on every SYNC, the torque offset 0x60B2 beside it at 0), which the drive then
    uses as its velocity feed-forward in place of its setpoints' difference.

    ``eds: FILE`` (relative to the bus config) makes the simulated drive present a vendor's
    EDS/DCF: its identity, objects and default PDOs (:mod:`.personality`)."""

    feed_forward: str = "none"
    eds: Path | None = None
    #: 0x1018:04, the identity an LSS master tells drives apart by (None: the EDS's)
    serial_number: int | None = None
    #: where the parameters saved by 0x1010 last across restarts (None: for the run)
    parameter_file: Path | None = None

    KEYS = ("feed_forward", "eds", "serial_number", "parameter_file")
    PATH_KEYS = ("eds", "parameter_file")

    @property
    def sends_velocity(self) -> bool:
        """Whether the master sends RPDO4 (the velocity offset) every cycle."""
        return self.feed_forward == "velocity"

    def check_notes(self) -> list[str]:
        """The vendor EDS's identity and the objects hil stores and reads back but gives no
        meaning to."""
        if self.eds is None:
            return []
        from hil.protocols.cia402.eds import objects_without_meaning, read_dictionary
        od = read_dictionary(self.eds)
        info = od.device_information
        stored = objects_without_meaning(od)
        return [f"personality {self.eds.name}: {info.vendor_name or 'vendor unnamed'} "
                f"{info.product_name or ''}".rstrip() + f"; {len(stored)} object(s) stored and "
                f"read back without meaning in hil:",
                *(f"  0x{index:04X} {name}" for index, name in stored),
                "hil's own master (hil control, hil up) expects hil's default PDO mapping: "
                "bring this drive up with your master and its DCF"]

    @classmethod
    def from_mapping(cls, values: dict) -> Cia402Options:
        eds = values.get("eds")
        if eds is not None and not isinstance(eds, str):
            raise ValueError(f"'eds' is the path of an EDS or DCF file, not {eds!r}")
        serial = values.get("serial_number")
        if serial is not None and (not isinstance(serial, int) or isinstance(serial, bool)
                                   or not 0 <= serial <= 0xFFFFFFFF):
            raise ValueError(f"'serial_number' is an UNSIGNED32 (0..4294967295), not {serial!r}")
        kept = values.get("parameter_file")
        if kept is not None and not isinstance(kept, str):
            raise ValueError(f"'parameter_file' is a file's path, not {kept!r}")
        options = cls(feed_forward=str(values.get("feed_forward", "none")),
                      eds=Path(eds) if eds is not None else None, serial_number=serial,
                      parameter_file=Path(kept) if kept is not None else None)
        if options.feed_forward not in FEED_FORWARD:
            raise ValueError(f"'feed_forward' is one of {', '.join(FEED_FORWARD)}, not "
                             f"'{options.feed_forward}'")
        if options.eds is not None:
            from hil.protocols.cia402.eds import read_dictionary    # canopen: lazily
            read_dictionary(options.eds)
        return options


class Cia402(Protocol):
    """CiA 402 drives with the EDS's default PDOs, synchronised by SYNC."""

    name = "cia402"
    # the SYNC (CiA 301 7.2.5), without a counter: hil's master leaves 0x1019 at 0
    cycle_end_frames = (Frame(SYNC_ID),)
    link_loss_codes = LINK_LOSS
    carries_torque_feed_forward = True
    unconfigured_node_id = UNCONFIGURED
    Options = Cia402Options
    # the objects the drive keeps them in, with the types of hil's EDS (CiA 301 for 0x1017,
    # CiA 402 for 0x6066, 0x6076 and 0x608F; 0x2010 is hil's own)
    setting_fields = {
        "heartbeat_period": SettingField(1000, 1, 0xFFFF, "0x1017 producer heartbeat time, "
                                                          "UNSIGNED16 ms"),
        "watchdog_timeout": SettingField(1000, 0, 0xFFFF, "0x2010 watchdog timeout, "
                                                          "UNSIGNED16 ms"),
        "following_error_timeout": SettingField(1000, 0, 0xFFFF, "0x6066 following error "
                                                                 "time out, UNSIGNED16 ms"),
        # a rated torque under 0.5 mN·m is 0 there (the pigot's finger): its master then
        # gives it no torque offset (Cia402Axis), so 0 is let through
        "rated_torque": SettingField(1000, 0, 0xFFFFFFFF, "0x6076 motor rated torque, "
                                                          "UNSIGNED32 mN·m"),
        "encoder_counts_per_rev": SettingField(1, 1, 0xFFFFFFFF, "0x608F:01 encoder "
                                                                 "increments, UNSIGNED32"),
    }
    drive = "hil.protocols.cia402.drive:Cia402Drive"
    axis = "hil.protocols.cia402.axis:Cia402Axis"

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float, options=None
                   ) -> list[FrameSpec]:
        """The default mapping's exchange: RPDO1 (controlword, target), TPDO1, TPDO2 per
        SYNC, and RPDO4 (velocity and torque offsets) with velocity feed-forward; heartbeat;
        EMCY and SDO only on events (their ids are reserved)."""
        if node_id == UNCONFIGURED:
            # LSS only, until a master assigns the node id (whose frames are then that id's)
            return [FrameSpec(LSS_REQUEST_ID, 8, 0.0, "LSS request"),
                    FrameSpec(LSS_ANSWER_ID, 8, 0.0, "LSS answer")]
        feed_forward = options is not None and options.sends_velocity
        return [FrameSpec(0x200 + node_id, 6, cycle_hz, "RPDO1"),
                FrameSpec(0x180 + node_id, 6, cycle_hz, "TPDO1"),
                FrameSpec(0x280 + node_id, 6, cycle_hz, "TPDO2"),
                FrameSpec(0x700 + node_id, 1, 1.0 / heartbeat_period, "heartbeat"),
                *([FrameSpec(0x500 + node_id, 6, cycle_hz, "RPDO4")] if feed_forward else []),
                FrameSpec(0x080 + node_id, 8, 0.0, "EMCY"),
                FrameSpec(0x580 + node_id, 8, 0.0, "SDO answer"),
                FrameSpec(0x600 + node_id, 8, 0.0, "SDO request")]

    @classmethod
    def description(cls) -> list[str]:
        from hil.protocols.cia402.summary import dictionary_summary   # loads canopen

        return dictionary_summary()

    @classmethod
    def bus_wide_frames(cls, cycle_hz: float) -> list[FrameSpec]:
        """The master's NMT commands (on events; the node addressed in byte 1) and its SYNC,
        empty, every cycle (CiA 301 7.2.8.3.1, 7.2.5)."""
        return [FrameSpec(NMT_ID, 2, 0.0, "NMT"), FrameSpec(SYNC_ID, 0, cycle_hz, "SYNC")]

    @classmethod
    def drive_problem(cls, node_id: int, options=None) -> str | None:
        """A drive without a node id and no serial number; else what in its files (a vendor's
        EDS, a parameter file) it would not start with (:mod:`.start_check`)."""
        if node_id == UNCONFIGURED and (options is None or options.serial_number is None):
            return ("a drive that boots without a node id (255, for an LSS master to assign) "
                    "needs options: {serial_number: N}, distinct on its bus: the identity "
                    "the master tells it by")
        if options is None or options.eds is None and options.parameter_file is None:
            return None
        from hil.protocols.cia402.start_check import start_problem     # canopen: lazily
        return start_problem(node_id, options)

    @classmethod
    def shared_ids(cls, options=None) -> set[int]:
        """The LSS ids: every unconfigured drive's until it has a node id."""
        return {LSS_REQUEST_ID, LSS_ANSWER_ID}

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """By CiA 301's predefined connection set (PDOs moved to other COB-IDs are not
        told), whose identifiers are 11-bit ones (CiA 301 7.3.5): no 29-bit frame is a
        drive's. A heartbeat of a node that is no drive is the master's own (or another
        master's on the bus): it goes to the drives, which may consume it (0x1016)."""
        if frame.extended:
            return None
        can_id, data = frame.identifier, frame.data
        if can_id == SYNC_ID:
            return FrameSource(Sender.MASTER, None, "SYNC", cycle=True)
        if can_id == TIME_ID:
            return FrameSource(Sender.MASTER, None, "TIME")
        if can_id in (LSS_REQUEST_ID, LSS_ANSWER_ID):     # CiA 305: no node id in either
            return (FrameSource(Sender.MASTER, None, "LSS request") if can_id == LSS_REQUEST_ID
                    else None)
        if can_id == NMT_ID:
            node = data[1] if len(data) == 2 else None
            if node not in (0, None) and node not in drives:
                return None
            return FrameSource(Sender.MASTER, node or None, "NMT")
        code, node = can_id & 0x780, can_id & 0x7F
        sender, what = FUNCTION_CODES.get(code, (None, ""))
        if sender is None:
            return None
        if node not in drives:
            return FrameSource(Sender.MASTER, None, what) if code == 0x700 else None
        return FrameSource(sender, node, what)

    @classmethod
    def source_reads_data(cls, frame: Frame, drives: Mapping[int, object]) -> bool:
        # the node addressed is the command's second byte
        return frame.identifier == NMT_ID and not frame.extended

    @classmethod
    def torque_feed_forward_frames(cls, node_id: int, cycle_hz: float, options=None
                                   ) -> list[FrameSpec]:
        """RPDO4 (the torque offset 0x60B2 beside the velocity offset), unless the velocity
        feed-forward sends it already."""
        if options is not None and options.sends_velocity:
            return []
        return [FrameSpec(0x500 + node_id, 6, cycle_hz, "RPDO4")]
