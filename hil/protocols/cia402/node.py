"""The CiA 301 slave of hil's CANopen drives: what a real node refuses, and when.

python ``canopen``'s LocalNode gives the object dictionary, the SDO server, the NMT slave
(boot-up, heartbeat), the EMCY producer and the PDO maps. It does not check what a master
writes into the PDO parameters (a mapping of a missing object is stored, and the drive
fails at the next NMT start), answers SDO in STOPPED, unpacks frames of any length (a short
NMT or SDO frame is a Python exception), follows no segmented-transfer state, and has no
heartbeat consumer. :class:`DriveNode` adds these as CiA 301 (and lely-core, the CANopen
stack under ros2_canopen) has them:

* NMT: only 2-byte commands; in STOPPED no SDO, EMCY or PDO (the profile drops PDOs); the
  heartbeat on the drive's clock, never between a reset and its boot-up;
* SDO (:mod:`.sdo`): only 8-byte requests; a segment without a transfer in progress is
  aborted (0x05040001); an expedited download without size takes the object's;
* PDO communication (0x1400.., 0x1800..) and mapping (0x1600.., 0x1A00..) parameters:
  the CiA 301 order of a remapping (make the PDO not valid, mapping count 0, entries,
  count, valid again) is enforced, and every entry is checked when the count is written:
  object missing (0x06020000), sub-index missing (0x06090011), not mappable or the wrong
  direction (0x06040041), a length other than the object's (0x06040043), over 64 bits
  (0x06040042), more entries than the mapping has (0x06090031); a changed CAN-ID of a valid
  PDO, an 11-bit COB-ID over 0x7FF or a restricted one (:mod:`.pdo_parameters`), a
  reserved or unsupported transmission type, an inhibit time or SYNC start value changed
  while valid: 0x06090030 (the checks that need no order: :mod:`.written`);
* heartbeat consumer (0x1016): monitors each producer configured there from its first
  heartbeat; :meth:`DriveNode.lost_heartbeats` names those overdue.

A frame refused for its form is counted in :attr:`DriveNode.refused` and reported through
``on_refused``, never raised.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import canopen
from canopen.emcy import EmcyProducer
from canopen.nmt import NmtSlave

from hil.protocols.cia402.pdo_parameters import NOT_VALID, PdoParameter, mapping_abort
from hil.protocols.cia402.ranges import range_abort
from hil.protocols.cia402.written import CONSUMER_HEARTBEAT, write_abort
from hil.protocols.cia402.sdo import DriveSdoServer
from canopen.sdo import SdoAbortedError
from canopen.sdo.constants import ABORT_INVALID_VALUE, ABORT_NO_SUBINDEX
from canopen.objectdictionary import NUMBER_TYPES

log = logging.getLogger(__name__)

STOPPED = "STOPPED"
#: canopen's code of OPERATIONAL (the heartbeat's state byte, CiA 301)
NMT_OPERATIONAL = 5
#: NMT commands that reset a node (application, communication)
RESETS = (0x81, 0x82)
#: SDO abort "resource not available" (canopen: an object without a value)
ABORT_NO_DATA = 0x060A0023


def normalise_access_types(od: canopen.ObjectDictionary) -> None:
    """Access types in canopen's lower case: vendors write "RW" (and a stray blank), which
    canopen, comparing as written, takes for neither readable nor writable."""
    for obj in od.values():
        entries = [obj] if isinstance(obj, canopen.objectdictionary.ODVariable) else obj.values()
        for entry in entries:
            entry.access_type = entry.access_type.strip().lower()


class DriveEmcyProducer(EmcyProducer):
    """canopen's EMCY producer, silent while its node is STOPPED (CiA 301)."""

    def __init__(self, cob_id: int, node: canopen.LocalNode):
        super().__init__(cob_id)
        self._node = node

    def send(self, code: int, register: int = 0, data: bytes = b"") -> None:
        if self._node.nmt.state != STOPPED:
            super().send(code, register, data)


class ClockedNmtSlave(NmtSlave):
    """canopen's NMT slave, its heartbeat sent by the drive's clock (:meth:`heartbeat_due`,
    under the drive's lock) instead of by a sending thread of its own: such a thread could
    put out a heartbeat between a reset command's arrival and the boot-up it answers with
    (CiA 301 7.2.8.3.2.1: the boot-up is the first frame a node sends after a reset, and
    masters start configuring on it)."""

    #: in OPERATIONAL now (PDOs processed, CiA 301): kept with the state, because every PDO
    #: and SYNC asks, and canopen's ``state`` property is a Python call and a name lookup
    operational = False

    def __init__(self, node_id: int, local_node, clock: Callable[[], float] = time.monotonic):
        super().__init__(node_id, local_node)
        #: the drive's clock, the one :meth:`heartbeat_due` is asked with
        self._clock = clock
        self._period = 0.0
        self._due: float | None = None

    # canopen keeps the state code in ``_state`` and sets it from several places (a command,
    # a local transition): the flag follows every write there
    @property
    def _state(self) -> int:
        return self._code

    @_state.setter
    def _state(self, code: int) -> None:
        self._code = code
        self.operational = code == NMT_OPERATIONAL

    def start_heartbeat(self, heartbeat_time_ms: int) -> None:
        self._heartbeat_time_ms = heartbeat_time_ms
        self._period = heartbeat_time_ms / 1000
        self._due = self._clock() if heartbeat_time_ms > 0 else None

    def stop_heartbeat(self) -> None:
        self._due = None

    def update_heartbeat(self) -> None:
        """Nothing to do: each heartbeat carries the state it is sent in."""

    def heartbeat_due(self, now: float) -> bytes | None:
        """The heartbeat to send at ``now``, if one is due; never in INITIALISING (a
        heartbeat of state 0 is a boot-up)."""
        if self._due is None or now < self._due or self._code == 0:
            return None
        # on its phase; after a stall past a whole period, one beat and a period from now
        # (a timer's missed expiries are one expiry: no burst of beats to catch up)
        self._due += self._period
        if self._due <= now:
            self._due = now + self._period
        return bytes([self._code])


class DriveNode(canopen.LocalNode):
    """A canopen LocalNode that refuses what a real CiA 301 slave refuses (module doc)."""

    def __init__(self, node_id: int, dictionary: canopen.ObjectDictionary,
                 on_refused: Callable[[int, str], None] = lambda can_id, why: None):
        super().__init__(node_id, dictionary)
        normalise_access_types(self.object_dictionary)
        self.sdo = DriveSdoServer(0x600 + self.id, 0x580 + self.id, self)
        self.emcy = DriveEmcyProducer(0x80 + self.id, self)
        # LocalNode registered its own NMT slave for 0x1017 writes: this one takes its place
        self._write_callbacks.remove(self.nmt.on_write)
        self.nmt = ClockedNmtSlave(self.id, self)
        self.add_write_callback(self.nmt.on_write)
        #: frames refused for their form (a wrong length)
        self.refused = 0
        self._on_refused = on_refused
        self._stored: list[Callable[[int, int], None]] = []
        # heartbeat consumer: producer node id -> (timeout s, last heard or None, reported)
        self._consumers: dict[int, list] = {}
        self._heartbeat_handlers: dict[int, Callable] = {}
        self.add_write_callback(self._check_write)

    # --- network -----------------------------------------------------------------------

    def associate_network(self, network: canopen.Network) -> None:
        # canopen's, with the NMT handler checking the frame's length first
        if self.has_network():
            raise RuntimeError("Node is already associated with a network")
        for service in (self, self.sdo, self.tpdo, self.rpdo, self.nmt, self.emcy):
            service.network = network
        network.subscribe(self.sdo.rx_cobid, self.sdo.on_request)
        network.subscribe(0, self._on_nmt)
        self.configure_heartbeat_consumers()

    def remove_network(self) -> None:
        if not self.has_network():
            return
        network = self.network
        network.unsubscribe(self.sdo.rx_cobid, self.sdo.on_request)
        network.unsubscribe(0, self._on_nmt)
        for can_id, handler in self._heartbeat_handlers.items():
            network.unsubscribe(can_id, handler)
        self._heartbeat_handlers = {}
        unset = canopen.network._UNINITIALIZED_NETWORK
        for service in (self, self.sdo, self.tpdo, self.rpdo, self.nmt, self.emcy):
            service.network = unset

    def _on_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) != 2:
            self.refuse(can_id, f"an NMT command of {len(data)} bytes (CiA 301: 2)")
            return
        if data[0] in RESETS and data[1] in (0, self.id):
            # CiA 301: a reset ends the heartbeat until the boot-up. canopen keeps its timer
            # running with the state INITIALISING (0), and a heartbeat of state 0 is a
            # boot-up: one sent before the drive's own reset was done (a replay under load
            # caught it) told the master the drive had rebooted twice
            self.nmt.stop_heartbeat()
        self.nmt.on_command(can_id, data, timestamp)

    def refuse(self, can_id: int, why: str) -> None:
        """A frame refused for its form: counted and reported, never raised."""
        self.refused += 1
        self._on_refused(can_id, why)

    # --- object dictionary -----------------------------------------------------------

    def on_stored(self, callback: Callable[[int, int], None]) -> None:
        """Call ``callback(index, subindex)`` after each write is stored (the write callbacks
        run before: they may refuse it)."""
        self._stored.append(callback)

    def get_data(self, index: int, subindex: int, check_readable: bool = False) -> bytes:
        self._check_exists(index, subindex)
        try:
            return super().get_data(index, subindex, check_readable)
        except SdoAbortedError as exc:
            if exc.code != ABORT_NO_DATA:
                raise
        # an object a vendor's EDS gives no DefaultValue and nothing wrote yet: hil's reading
        # is the zero of its type (a device has some value; canopen aborts 0x060A0023)
        entry = self._find_object(index, subindex)
        return entry.encode_raw(0) if entry.data_type in NUMBER_TYPES else b""

    def set_data(self, index: int, subindex: int, data: bytes,
                 check_writable: bool = False) -> None:
        self._check_exists(index, subindex)
        super().set_data(index, subindex, data, check_writable)
        if index == CONSUMER_HEARTBEAT:
            self.configure_heartbeat_consumers()
        for callback in self._stored:
            callback(index, subindex)

    def _check_exists(self, index: int, subindex: int) -> None:
        """canopen makes up any sub-index of an ARRAY on demand: the EDS's are the ones."""
        entry = self.object_dictionary.get(index)
        if isinstance(entry, canopen.objectdictionary.ODArray) and \
                subindex not in entry.subindices:
            raise SdoAbortedError(ABORT_NO_SUBINDEX)

    def value(self, index: int, subindex: int = 0) -> int:
        """The object's value as stored (or its default); 0 where the object dictionary (a
        vendor's) lacks the object or sub-index, the CiA 301 default of the communication
        parameters read this way (inhibit time, event timer, heartbeat consumer entries)."""
        entry = self.object_dictionary.get(index)
        if entry is not None and not isinstance(entry, canopen.objectdictionary.ODVariable):
            entry = entry.subindices.get(subindex)
        if entry is None:
            return 0
        return entry.decode_raw(self.get_data(index, subindex))

    def pdo_valid(self, communication_index: int) -> bool:
        return not self.value(communication_index, 1) & NOT_VALID

    def _check_write(self, index: int, subindex: int, od, data: bytes, **_) -> None:
        """A write as :func:`.written.write_abort` checks it, after the order CiA 301 gives
        a PDO's remapping (:meth:`_order_abort`)."""
        code = range_abort(od, data)
        parameter = PdoParameter.of(index)
        if code is None and parameter is not None and od.data_type in NUMBER_TYPES:
            code = self._order_abort(parameter, subindex, od.decode_raw(data))
        if code is None:
            code = write_abort(self, index, subindex, od, data)
        if code is not None:
            raise SdoAbortedError(code)

    def _order_abort(self, parameter: PdoParameter, subindex: int, value: int) -> int | None:
        """A PDO's parameters change while it is not valid (CiA 301 7.5.2.35-38: COB-ID's
        CAN-ID, inhibit time, SYNC start value, the mapping), a mapping's entries while its
        count is 0; the count is checked over the entries it then counts."""
        valid = self.pdo_valid(parameter.communication_index)
        if parameter.mapping:
            if valid:
                return ABORT_INVALID_VALUE                   # make the PDO not valid first
            if subindex == 0:
                return mapping_abort(self, parameter, value)
            if self.value(parameter.mapping_index, 0) != 0:
                return ABORT_INVALID_VALUE                   # set the count to 0 first
            return None
        if subindex == 1:
            old = self.value(parameter.communication_index, 1)
            if valid and not value & NOT_VALID and (value ^ old) & 0x1FFFFFFF:
                return ABORT_INVALID_VALUE                   # make it not valid first
        elif subindex in (3, 6) and valid and value != self.value(
                parameter.communication_index, subindex):
            return ABORT_INVALID_VALUE                       # inhibit time, SYNC start value
        return None

    # --- heartbeat consumer ------------------------------------------------------------

    def configure_heartbeat_consumers(self) -> None:
        """(Re)start monitoring the producers 0x1016 names; each from its first heartbeat."""
        if not self.has_network():
            return
        network = self.network
        for can_id, handler in self._heartbeat_handlers.items():
            network.unsubscribe(can_id, handler)
        self._heartbeat_handlers, self._consumers = {}, {}
        consumers = self.object_dictionary.get(CONSUMER_HEARTBEAT)
        for sub in consumers.subindices if consumers is not None else ():
            value = self.value(CONSUMER_HEARTBEAT, sub) if sub else 0
            producer, period = (value >> 16) & 0xFF, value & 0xFFFF
            if producer and period:
                self._consumers[producer] = [period / 1000.0, None, False]
                handler = self._heartbeat_from(producer)
                self._heartbeat_handlers[0x700 + producer] = handler
                network.subscribe(0x700 + producer, handler)

    def _heartbeat_from(self, producer: int) -> Callable[[int, bytes, float], None]:
        def heard(can_id: int, data: bytes, timestamp: float) -> None:
            consumer = self._consumers.get(producer)
            if consumer is not None and len(data) == 1:
                consumer[1], consumer[2] = time.monotonic(), False
        return heard

    def lost_heartbeats(self, now: float) -> list[int]:
        """Producers whose heartbeat is overdue, each named once until heard again."""
        lost = []
        for producer, consumer in self._consumers.items():
            timeout, heard, reported = consumer
            if heard is not None and not reported and now - heard > timeout:
                consumer[2] = True
                lost.append(producer)
        return lost
