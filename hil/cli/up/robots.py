"""One robot under ``hil up``: its config, its processes and what is followed of its run."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from hil.bus_config import SystemConfig
from hil.cli.run_progress import Progress
from hil.supervisor import Child


@dataclass
class RobotRun:
    """One robot under ``hil up``: its config, its sim and controller, and what is followed
    of its run."""

    config_path: Path
    config: SystemConfig
    progress: Progress
    children: dict[str, Child] = field(default_factory=dict)
    #: whether its demo (if any) succeeded
    demo_succeeded: bool = True

    @property
    def name(self) -> str:
        return self.config.robot.name

    @property
    def label(self) -> str:
        """Before what ``hil up`` says of this robot ("" with one robot, "ur3: " with
        several)."""
        return self.progress.label
