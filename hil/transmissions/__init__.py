"""Transmissions: pure maps between actuator space and joint space.

:func:`build_transmission` turns a description's :class:`TransmissionSpec`
into a map, choosing the class by the URDF type string from one table.
"""

from __future__ import annotations

from hil.description import TRANSMISSION_TYPES, RobotDescription, TransmissionSpec
from hil.transmissions.base import Transmission, TransmissionStack
from hil.transmissions.differential import DifferentialTransmission
from hil.transmissions.four_bar import FourBarLinkageTransmission
from hil.transmissions.simple import SimpleTransmission

__all__ = [
    "DifferentialTransmission", "FourBarLinkageTransmission", "SimpleTransmission",
    "Transmission", "TransmissionStack", "build_transmission", "build_transmissions",
]


def _simple(spec: TransmissionSpec) -> Transmission:
    (joint,), (actuator,) = spec.joints, spec.actuators
    # ROS 1 writes the reduction on the actuator, ROS 2 on the joint; the other is 1.
    return SimpleTransmission(joint.name, actuator.name, actuator.reduction * joint.reduction,
                              joint.offset)


def _coupled(cls):
    def build(spec: TransmissionSpec) -> Transmission:
        return cls(tuple(j.name for j in spec.joints), tuple(a.name for a in spec.actuators),
                   tuple(a.reduction for a in spec.actuators),
                   tuple(j.reduction for j in spec.joints),
                   tuple(j.offset for j in spec.joints))
    return build


#: Builders by the kind names of :data:`hil.description.TRANSMISSION_TYPES`.
TRANSMISSION_BUILDERS = {
    "simple": _simple,
    "differential": _coupled(DifferentialTransmission),
    "four_bar": _coupled(FourBarLinkageTransmission),
}


def build_transmission(spec: TransmissionSpec) -> Transmission:
    """The map for one validated transmission spec."""
    return TRANSMISSION_BUILDERS[TRANSMISSION_TYPES[spec.type]](spec)


def build_transmissions(description: RobotDescription) -> tuple[Transmission, ...]:
    return tuple(build_transmission(spec) for spec in description.transmissions)
