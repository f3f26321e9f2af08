"""What ``hil up`` writes: the rerun recording (whole, or its segments), the CAN log and the
processes' logs; each checked before the run begins, the previous run's, replaced, named
(:mod:`hil.cli.written_files`, as ``hil viz`` and ``hil replay`` do). Keep a run by moving
it, or by giving the next run another ``--save``."""

from __future__ import annotations

from pathlib import Path

from hil.cli.written_files import previous_outputs
from hil.errors import UsageError


def replace_previous(save: Path, can_log: Path, logs: Path) -> list[str]:
    """The previous run's outputs this run replaces, in words (empty: none); UsageError
    naming an output that cannot be written, before anything is replaced."""
    if logs.exists() and not logs.is_dir():
        raise UsageError.single(f"the process logs' folder '{logs}' (beside --save) is a file",
                                hint="move it, or give --save another name")
    found = previous_outputs({"--save": save, "--can-log": can_log}, recording=save)
    if logs.is_dir() and any(logs.iterdir()):
        found.append(f"the process logs in {logs}/")
    return found
