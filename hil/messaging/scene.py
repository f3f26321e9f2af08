"""The plant's scene as the simulator publishes it (``hil_msgs/SceneState``): where each
moving object is, where a floating base is, and where things touch, a few dozen times a
second, for the recording."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.messaging import cdr


@dataclass(frozen=True)
class SceneState:
    """One moment of the scene; arrays are (objects, 3|4) and (contacts, 3), world frame."""

    wall_time: float                 # s since the epoch
    sim_time: float                  # s of plant time
    names: tuple[str, ...]           # the moving objects
    positions: np.ndarray            # m
    orientations: np.ndarray         # quaternions w, x, y, z
    contact_points: np.ndarray       # m
    contact_forces: np.ndarray       # N, on each contact's first body
    #: a floating base's position (m) and orientation (w, x, y, z); None for a fixed one
    base: tuple[np.ndarray, np.ndarray] | None = None

    def encode(self) -> bytes:
        position, orientation = self.base if self.base is not None else ((), ())
        return cdr.encode(cdr.msg(
            cdr.SCENE_STATE, wall_time=self.wall_time, sim_time=self.sim_time,
            names=list(self.names), position=self.positions.ravel(),
            orientation=self.orientations.ravel(), contact_point=self.contact_points.ravel(),
            contact_force=self.contact_forces.ravel(), base_position=np.asarray(position),
            base_orientation=np.asarray(orientation)))

    @classmethod
    def decode(cls, data: bytes) -> SceneState:
        """Raise ValueError naming what is wrong with a malformed payload."""
        message = cdr.decode(data, cdr.SCENE_STATE)
        objects = len(message.names)
        contacts = len(message.contact_point) // 3

        def table(name: str, rows: int, width: int) -> np.ndarray:
            values = np.asarray(getattr(message, name), dtype=float)
            if len(values) != rows * width:
                raise ValueError(f"malformed {cdr.SCENE_STATE}: '{name}' has {len(values)} "
                                 f"values, {rows} x {width} expected")
            return values.reshape(rows, width)

        base = ((table("base_position", 1, 3)[0], table("base_orientation", 1, 4)[0])
                if len(message.base_position) or len(message.base_orientation) else None)
        return cls(message.wall_time, message.sim_time, tuple(message.names),
                   table("position", objects, 3), table("orientation", objects, 4),
                   table("contact_point", contacts, 3), table("contact_force", contacts, 3),
                   base)
