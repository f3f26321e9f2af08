"""python-can's ``fd`` option on hil's own buses (``hil-virtual``, ``zenoh``), as Linux's
SocketCAN gives it to a raw socket (``CAN_RAW_FD_FRAMES``, Documentation/networking/can.rst,
"RAW socket option CAN_RAW_FD_FRAMES"): a bus opened without it refuses to send a CAN FD
frame (the kernel's EINVAL, python-can's CanOperationError) and hears none (the kernel does
not pass one to such a socket). A client that forgets ``fd=True`` on an FD bus meets here
what it meets on the hardware: its FD frames refused, the devices' FD answers unheard.
hil's own ends open every bus with it (:func:`hil.bus_config.open_buses`): a classical
bus' drives see a stray FD frame, to report it (:class:`hil.can.router.FrameRouter`).
"""

from __future__ import annotations

import can
from can import CanProtocol


def fd_protocol(fd: bool, kwargs: dict) -> CanProtocol:
    """The bus' ``protocol`` (python-can's :attr:`can.BusABC.protocol`) for its ``fd``
    option, unless ``kwargs`` name one (python-can's own ``virtual`` takes ``protocol``)."""
    return kwargs.pop("protocol", CanProtocol.CAN_FD if fd else CanProtocol.CAN_20)


def takes_fd(protocol: CanProtocol) -> bool:
    return protocol is not CanProtocol.CAN_20


def refuse_fd_send(channel_info: str, msg: can.Message) -> None:
    """Raise for an FD frame sent on a bus opened without ``fd``."""
    raise can.CanOperationError(
        f"{channel_info}: cannot send a CAN FD frame (id 0x{msg.arbitration_id:X}) on a bus "
        "opened without fd=True (SocketCAN refuses it the same: EINVAL); open it with "
        "can.Bus(..., fd=True)")
