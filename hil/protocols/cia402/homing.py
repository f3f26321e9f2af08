"""CiA 402 homing methods a bench can emulate, as moves of the drive's own profile.

The limit switches are the drive's position limits (0x607D, from the joint's limits: where
the joint would hit its stop), the index pulse is the encoder's zero, once a motor
revolution. Methods (CiA 402 homing mode, method numbers of 0x6098):

* 17 / 18: to the negative / positive limit switch at the switch search speed (0x6099:01);
* 1 / 2: the same, then back to the first index pulse inside the limit at the zero search
  speed (0x6099:02);
* 33 / 34: to the next index pulse below / above the present position (zero search speed);
* 35 / 37: the present position (no move).

Every move accelerates at the homing acceleration 0x609A. At the end the drive's position
scale is shifted so that the position reads the home offset 0x607C (CiA 402: the home
position is the zero plus the home offset): homing attained. A method whose switch does not
exist (no position limit), a zero speed or acceleration: homing error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from hil.drives.core import DriveCore

TURN = 2 * math.pi
#: methods by what they look for first
NEGATIVE_SWITCH, POSITIVE_SWITCH = (1, 17), (2, 18)
INDEX_BELOW, INDEX_ABOVE, HERE = 33, 34, (35, 37)
METHODS = (*NEGATIVE_SWITCH, *POSITIVE_SWITCH, INDEX_BELOW, INDEX_ABOVE, *HERE)


@dataclass
class HomingSpeeds:
    """0x6099:01, 0x6099:02 (rad/s) and 0x609A (rad/s^2), motor side."""

    switch: float = 0.0
    zero: float = 0.0
    acceleration: float = 0.0


class Homing:
    """One homing run in progress: the moves left, and the parameters to restore."""

    def __init__(self, core: DriveCore, method: int, speeds: HomingSpeeds):
        self.core = core
        self._saved = core.parameters
        self.failed = False
        self._moves = self._plan(method, speeds)

    def _plan(self, method: int, speeds: HomingSpeeds) -> list[tuple[float, float]]:
        """(target, speed) of each move, in the drive's position scale."""
        if method in HERE:
            return []
        here = self.core.status().position
        low, high = self.core.parameters.position_limits or (-math.inf, math.inf)
        moves = []
        if method in NEGATIVE_SWITCH + POSITIVE_SWITCH:
            switch = low if method in NEGATIVE_SWITCH else high
            if not math.isfinite(switch):
                self.failed = True
                return []
            moves.append((switch, speeds.switch))
            here = switch
        if method == 1 or method == INDEX_ABOVE:
            moves.append((self._index(here, up=True), speeds.zero))
        elif method == 2 or method == INDEX_BELOW:
            moves.append((self._index(here, up=False), speeds.zero))
        if any(speed <= 0 or not low <= target <= high for target, speed in moves) or (
                moves and speeds.acceleration <= 0):
            self.failed = True               # a zero speed, an index pulse past a limit
            return []
        self._acceleration = speeds.acceleration
        return moves

    def _index(self, position: float, up: bool) -> float:
        """The next index pulse (encoder zero) strictly above or below ``position``."""
        turns = (position - self.core.offset) / TURN
        k = math.floor(turns) + 1 if up else math.ceil(turns) - 1
        return self.core.offset + k * TURN

    def advance(self) -> bool:
        """Start the next move once the last is done; True when the last one has ended."""
        if self.failed or not self.core.move_done:
            return self.failed
        if not self._moves:
            self.core.parameters = self._saved
            return True
        target, speed = self._moves.pop(0)
        self.core.parameters = replace(self._saved, profile_velocity=speed,
                                       profile_acceleration=self._acceleration,
                                       profile_deceleration=self._acceleration)
        self.core.move_to(target)
        return False

    def abandon(self) -> None:
        """Stopped before its end (halt, disable, another mode): the profile as it was."""
        self.core.parameters = self._saved
