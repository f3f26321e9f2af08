"""The master's side of one CiA 402 drive: bring-up over SDO/NMT, cyclic PDOs.

Bring-up uses python ``canopen`` (NMT, SDO client, PDO map upload) on the bus' router
(:mod:`.network`); the cyclic exchange packs and parses its PDOs by hand with ``struct``, as
the router's own frames and handlers, because it runs every cycle for every axis and must
stay cheap and allocation-light.
"""

from __future__ import annotations

import math
import struct
import time

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame, frame_of_fields
from hil.can.router import FrameRouter, Subscription
from hil.errors import HilError
from hil.hardware.axis import Axis, AxisCommand, AxisFault, FaultKind
from hil.protocols.cia402 import FRAME_ERRORS, UNCONFIGURED, Cia402, Cia402Options, emcy_words
from hil.resources import eds_path

#: NMT states in a heartbeat (CiA 301)
BOOT_UP, OPERATIONAL, PRE_OPERATIONAL = 0x00, 0x05, 0x7F
#: the default mapping's PDOs, as the master packs and reads them (hil's bench's bare master
#: too: hil.bench.bare_master)
RPDO1 = struct.Struct("<Hi")        # controlword, target position
TPDO1 = struct.Struct("<Hi")        # statusword, position actual
_TPDO2 = struct.Struct("<ih")       # velocity actual, torque actual
_RPDO4 = struct.Struct("<ih")       # velocity offset, torque offset
# their sizes as ints: a Struct's size is a C getter, read unspecialised at every answer
_TPDO1_SIZE, _TPDO2_SIZE = TPDO1.size, _TPDO2.size


def _int32(value: float) -> int:
    """A value for an INTEGER32 object, clamped as a drive would (the drive's own is in
    ``.state``, compiled, which the controller's side never loads)."""
    return max(-2**31, min(2**31 - 1, round(value)))

# canopen's State402 controlwords and statusword masks (CiA 402), written here: this module
# is compiled with the axis seam, which hil.hardware loads, and canopen (imported below where
# a drive is made or configured) must not load with it where no bus is CiA 402
# (tests/test_package.py); tests/test_cia402_master_axis.py holds them to canopen's
SHUTDOWN, SWITCH_ON, ENABLE, QUICK_STOP, DISABLE_VOLTAGE = 0x06, 0x07, 0x0F, 0x02, 0x00
FAULT_RESET = 0x80          # bit 7: fault reset (its rising edge)
#: state name -> (mask, value) of the statusword
SW_MASK = {"NOT READY TO SWITCH ON": (0x4F, 0x00), "SWITCH ON DISABLED": (0x4F, 0x40),
           "READY TO SWITCH ON": (0x6F, 0x21), "SWITCHED ON": (0x6F, 0x23),
           "OPERATION ENABLED": (0x6F, 0x27), "FAULT": (0x4F, 0x08),
           "FAULT REACTION ACTIVE": (0x4F, 0x0F), "QUICK STOP ACTIVE": (0x6F, 0x07)}
#: the controlword that walks a drive up from each state toward OPERATION ENABLED
WALK_UP = {"SWITCH ON DISABLED": SHUTDOWN, "READY TO SWITCH ON": SWITCH_ON,
            "SWITCHED ON": ENABLE, "OPERATION ENABLED": ENABLE}


def _state_of_bits(bits: int) -> str:
    for name, (mask, value) in SW_MASK.items():
        if bits & mask == value:
            return name
    return "UNKNOWN"


#: the state of each value of a statusword's state bits (0, 1, 2, 3, 5, 6: canopen's masks
#: ask no others), looked up by index at every answer
_STATE_BITS = 0x6F
_STATES = tuple(_state_of_bits(bits) for bits in range(_STATE_BITS + 1))


def state_of(statusword: int) -> str:
    """The CiA 402 state name of a statusword (canopen's mask table, SW_MASK)."""
    return _STATES[statusword & _STATE_BITS]


class Cia402Axis(Axis):
    """One CiA 402 drive as the master sees it."""

    protocol = Cia402

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        import canopen  # noqa: PLC0415 (the comment above SW_MASK says why)
        self.node = canopen.RemoteNode(config.node_id, str(eds_path()))
        self.counts_per_rad = config.encoder_counts_per_rev / (2 * math.pi)
        self.rated_torque = config.rated_torque
        self.controlword = SHUTDOWN
        self.take_statusword(0)
        self.last_emcy: int | None = None
        self._emcy_cycle = 0          # the master's cycle when it arrived
        self._operational = False     # its heartbeat said OPERATIONAL since configure()
        #: RPDO4 beside each target: the trajectory's velocity (velocity offset 0x60B1)
        #: and a torque feed-forward (torque offset 0x60B2), either as the config asks
        self.sends_velocity = (config.options or Cia402Options()).sends_velocity
        self.feed_forward = self.sends_velocity or config.torque_feed_forward != "none"

    # --- network hooks ----------------------------------------------------------

    def subscriptions(self) -> list[Subscription]:
        node_id = self.node_id
        return [Subscription(0x180 + node_id, self._on_tpdo1),
                Subscription(0x280 + node_id, self._on_tpdo2),
                Subscription(0x080 + node_id, self._on_emcy),
                Subscription(0x700 + node_id, self._on_heartbeat)]

    def attach(self, router: FrameRouter) -> None:
        """canopen's node (SDO client, NMT, PDO maps) on a network of its own on ``router``,
        before this axis' own handlers."""
        from hil.protocols.cia402.network import RoutedNetwork  # noqa: PLC0415 (canopen's)
        RoutedNetwork(router).add_node(self.node)
        super().attach(router)

    def _on_tpdo1(self, frame: Frame) -> None:
        data = frame.data
        if len(data) == _TPDO1_SIZE:
            statusword, counts = TPDO1.unpack(data)
            self.take_statusword(statusword)
            self.feedback.position = counts / self.counts_per_rad
            self.answered()

    def _on_tpdo2(self, frame: Frame) -> None:
        data = frame.data
        if len(data) == _TPDO2_SIZE:
            velocity, torque = _TPDO2.unpack(data)
            self.feedback.velocity = velocity / self.counts_per_rad
            self.feedback.torque = torque * self.rated_torque / 1000

    def _on_emcy(self, frame: Frame) -> None:
        data = frame.data
        if len(data) >= 2:
            code = struct.unpack_from("<H", data)[0]
            if code == 0x0000:
                # "error reset or no error" (CiA 301): the error it ends is still this
                # master's to report (a quick stop the next ENABLE undid); a fault reset
                # forgets it
                return
            self.last_emcy = code
            self._emcy_cycle = self._cycle

    def _on_heartbeat(self, frame: Frame) -> None:
        self.last_heard = time.monotonic()
        data = frame.data
        if not data:
            return
        state = data[0]
        if state == OPERATIONAL and self.configured:
            self._operational = True
        # booted again: its boot-up, or (the boot-up lost while the link was down) back in
        # PRE-OPERATIONAL after it had been started, which this master never asks for
        if self.configured and (state == BOOT_UP or state == PRE_OPERATIONAL
                                and self._operational):
            self.rebooted = True
            self._operational = False
            self.take_statusword(0)        # its state before the reboot is gone
        if state == BOOT_UP:
            self.booted.set()

    # --- bring-up ------------------------------------------------------------------

    def reset(self) -> None:
        """NMT reset node: the drive boots afresh and sends its boot-up message."""
        super().reset()
        self.node.nmt.send_command(0x81)

    def configure(self) -> None:
        """After boot: check the device, read its units and PDO maps, select CSP (SDO)."""
        if self.node_id == UNCONFIGURED:
            raise HilError.single(f"{self.label} boots without a node id (255): hil's own "
                                  "master assigns none (LSS, CiA 305)",
                                  hint="give it a node id in the bus config, or bring it up "
                                       "with your LSS master")
        import canopen  # noqa: PLC0415 (loaded by __init__ already)
        # canopen's default answer timeout (0.3 s) unless the master waits longer
        self.node.sdo.RESPONSE_TIMEOUT = max(canopen.sdo.client.SdoClient.RESPONSE_TIMEOUT,
                                             self.request_timeout)
        try:
            device_type = self.node.sdo[0x1000].raw
            if device_type & 0xFFFF != 402:
                raise HilError.single(f"{self.label} is not a CiA 402 drive (device type "
                                      f"0x{device_type:08X})",
                                      hint="check node_id and protocol in the bus config")
            resolution = self.node.sdo[0x608F][1].raw
            if resolution != self.config.encoder_counts_per_rev:
                raise HilError.single(
                    f"{self.label} reports {resolution} encoder counts/rev (0x608F), the bus "
                    f"config says {self.config.encoder_counts_per_rev}",
                    hint="make encoder_counts_per_rev match the drive")
            self.rated_torque = self.node.sdo[0x6076].raw / 1000
            self.node.tpdo.read()
            self.node.rpdo.read()
            self._check_mapping()
            if self.feed_forward:       # valid from now on: the drive maps and applies it
                self.node.sdo[0x1403][1].raw = 0x500 + self.node_id
            for pdo in self.node.tpdo.map.values():   # read() subscribed them; the frames
                if pdo.enabled:                       # come to this axis' own handlers
                    self.node.network.unsubscribe(pdo.cob_id, pdo.on_message)
            self.node.sdo[0x6060].raw = 8        # cyclic synchronous position
            self.node.nmt.send_command(0x01)     # start: operational
            self.configured, self.rebooted, self._operational = True, False, False
            # what it said before (a reboot) is no longer its state: walk it up from its
            # first answer, never from a state and position it had before it restarted
            self.take_statusword(0)
            self.feedback.heard = False
        except canopen.SdoCommunicationError as exc:
            raise HilError.single(f"{self.label} does not answer SDO: {exc}",
                                  hint="is the drive powered and on this bus?") from None
        except canopen.SdoAbortedError as exc:
            raise HilError.single(f"{self.label} refused an SDO request: {exc}") from None

    def _check_mapping(self) -> None:
        expected = {("rpdo", 1): [0x6040, 0x607A], ("tpdo", 1): [0x6041, 0x6064],
                    ("tpdo", 2): [0x606C, 0x6077]}
        if self.feed_forward:
            expected["rpdo", 4] = [0x60B1, 0x60B2]
        for (kind, number), indices in expected.items():
            pdo = getattr(self.node, kind)[number]
            found = [v.index for v in pdo.map]
            if found != indices or not (pdo.enabled or (kind, number) == ("rpdo", 4)):
                raise HilError.single(
                    f"{self.label} {kind.upper()}{number} maps "
                    f"{', '.join(f'0x{i:04X}' for i in found) or 'nothing'}; hil expects "
                    f"{', '.join(f'0x{i:04X}' for i in indices)} (the EDS default)",
                    hint="restore the drive's default PDO mapping")

    # --- cyclic ------------------------------------------------------------------------

    #: the state ``statusword`` says, kept with it (read several times a cycle)
    state: str = state_of(0)
    enabled: bool = False

    def take_statusword(self, statusword: int) -> None:
        """The drive's statusword, from its answer (or 0: its state unknown)."""
        self.statusword = statusword
        self.state = state = state_of(statusword)
        self.enabled = state == "OPERATION ENABLED"

    def cycle_frames(self, command: AxisCommand) -> list[Frame]:
        target, velocity, torque = command.target, command.velocity, command.torque
        stopping, enabling = command.stopping, command.holding
        controlword = self.next_controlword(stopping)
        # until the axis follows setpoints, its setpoint is where it is (no jump on enable)
        following = self.enabled and not enabling
        # built from C (Frame's own __new__ is a Python call a frame)
        frames = [frame_of_fields((0x200 + self.node_id,
                                   self.rpdo(controlword, target if following
                                             else self.feedback.position),
                                   False, False, False, False, False, 0.0))]
        if self.feed_forward:
            moving = following and not stopping
            speed = velocity * self.counts_per_rad if moving and self.sends_velocity else 0.0
            # the torque offset, per mille of the rated torque (0x6076; a drive whose rated
            # torque rounds to 0 mN·m cannot be given one), INTEGER16: whenever enabled
            # (holding too, so that the loops' integral never carries it twice)
            offset = (max(-32768, min(32767, round(1000 * torque / self.rated_torque)))
                      if torque and self.rated_torque > 0 and self.enabled and not stopping
                      else 0)
            frames.append(frame_of_fields((0x500 + self.node_id,
                                           _RPDO4.pack(_int32(speed), offset),
                                           False, False, False, False, False, 0.0)))
        return frames

    def disable_rounds(self) -> list[list[Frame]]:
        return [[Frame(0x200 + self.node_id, self.rpdo(word, self.feedback.position))]
                for word in (SHUTDOWN, DISABLE_VOLTAGE)]

    def forget_faults(self) -> None:
        self.last_emcy = None

    def next_controlword(self, stopping: bool) -> int:
        """Walk the 402 state machine toward OPERATION ENABLED, or quick-stop.

        Not stopping, a drive in FAULT is reset (a rising edge of bit 7) and one in
        QUICK STOP ACTIVE is disabled, and both walk up again from SWITCH ON DISABLED.
        """
        state = self.state
        if stopping:
            return QUICK_STOP if state == "OPERATION ENABLED" or state == "QUICK STOP ACTIVE" \
                else SHUTDOWN
        if state == "FAULT":
            self.controlword = SHUTDOWN if self.controlword == FAULT_RESET else FAULT_RESET
            return self.controlword
        if state == "QUICK STOP ACTIVE":
            return DISABLE_VOLTAGE
        if state == "SWITCHED ON" and not self.at_standstill():
            # enable only at standstill and with last cycle's position as the setpoint: a
            # brake-less axis still falling is caught where it comes to rest, not mid-fall
            return SWITCH_ON
        return WALK_UP.get(state, SHUTDOWN)

    def rpdo(self, controlword: int, target: float) -> bytes:
        counts = round(target * self.counts_per_rad)
        # clamped only where out of range: _int32's calls are a cycle's cost in the common case
        return RPDO1.pack(controlword, counts if -2**31 <= counts < 2**31 else _int32(counts))

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if self.rebooted:
            return self.found(FaultKind.REBOOTED, "booted again mid-run (a power cycle, or its "
                              "host restarted) and lost its configuration: a fault reset "
                              "configures it again")
        code = self.last_emcy or None
        if self.state == "QUICK STOP ACTIVE" and not stopping:
            why = f" after {emcy_words(code)}" if code else ""
            return self.found(FaultKind.QUICK_STOP, f"quick-stopped on its own{why}", code)
        if self.state in ("FAULT", "FAULT REACTION ACTIVE"):
            return self.found(FaultKind.FAULT,
                              f"is in FAULT: {emcy_words(code) if code else 'fault'}", code)
        if code and code not in FRAME_ERRORS and self.feedback.cycle > self._emcy_cycle:
            # an error EMCY and, in an answer sampled after it, no FAULT: e.g. an RPDO timeout
            # quick-stop that this master's next ENABLE undid at once (transition 16). The
            # drive still acted on its own, and the goal must know
            return self.found(FaultKind.REPORTED, f"reported {emcy_words(code)}", code)
        return None
