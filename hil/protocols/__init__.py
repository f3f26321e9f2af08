"""Drive protocols, one folder each: codec and description (``__init__``), simulated drive
(``drive``), master-side axis (``axis``). The sensors' wires sit beside them as codecs only
(``wit``, ``hipnuc``, and ``imu``: what every IMU's wire carries): a sensor is no drive, and
no :class:`Protocol` of this table.

:func:`protocol` finds one by the ``protocol`` name of a bus config: hil's own in
:data:`BUILTIN`, and any an installed package registers under the entry-point group
``hil.protocols`` (as python-can finds third-party interfaces under ``can.interface``)::

    [project.entry-points."hil.protocols"]
    mydrive = "mypackage.mydrive:MyDrive"      # a hil.protocols.base.Protocol
"""

from __future__ import annotations

import functools
from importlib.metadata import entry_points

from hil.errors import did_you_mean
from hil.protocols.base import FrameSource, Protocol, Sender, SettingField, load

#: hil's own protocols: name -> "module:Class" of their Protocol
BUILTIN = {"cia402": "hil.protocols.cia402:Cia402", "odrive": "hil.protocols.odrive:ODrive",
           "mit": "hil.protocols.mit:Mit", "damiao": "hil.protocols.damiao:Damiao",
           "cubemars": "hil.protocols.cubemars:CubeMars",
           "moteus": "hil.protocols.moteus:Moteus",
           "robstride": "hil.protocols.robstride:Robstride",
           "myactuator": "hil.protocols.myactuator:MyActuator"}
ENTRY_POINT_GROUP = "hil.protocols"


@functools.cache
def _registered() -> dict[str, str]:
    found = {point.name: point.value for point in entry_points(group=ENTRY_POINT_GROUP)}
    return {**found, **BUILTIN}            # an installed package cannot replace hil's own


def names() -> list[str]:
    """Every protocol a bus config may name."""
    return sorted(_registered())


@functools.cache
def protocol(name: str) -> type[Protocol]:
    """The protocol of that name; KeyError, naming a close one, if none is registered."""
    if name not in _registered():
        raise KeyError(f"no protocol '{name}'{did_you_mean(name, _registered())}; hil knows "
                       f"{', '.join(names())}")
    found = load(_registered()[name])
    if not (isinstance(found, type) and issubclass(found, Protocol)):
        raise TypeError(f"protocol '{name}' ({_registered()[name]}) is not a "
                        "hil.protocols.base.Protocol")
    return found


__all__ = ["BUILTIN", "ENTRY_POINT_GROUP", "FrameSource", "Protocol", "Sender", "SettingField",
           "names", "protocol"]
