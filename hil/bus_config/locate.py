"""Where a bus config is: a path, or a robot's name, looked for in this order (the first
found is taken): ``./NAME.yaml`` (where ``hil init NAME`` writes it), ``./bus_config/
NAME.yaml`` (a project laid out as hil's own), then the one hil ships. hil's choice: the
folder the user works in first, as a path given would be read from it."""

from __future__ import annotations

from pathlib import Path

from hil.errors import UsageError, did_you_mean
from hil.resources import BUS_CONFIGS, data_dir


def shipped_names() -> str:
    """The robots' names whose bus configs hil ships, for a command's help and messages
    ("openarm, openarm_teleop, pigot, ...")."""
    return ", ".join(sorted(p.stem for p in data_dir(BUS_CONFIGS).glob("*.yaml")))


def search_folders() -> tuple[Path, ...]:
    """Where a robot's name is looked for, in order."""
    return (Path("."), Path("bus_config"), data_dir(BUS_CONFIGS))


def config_path(name: str) -> Path:
    """A bus config: a path, or a robot's name (the module doc's search order)."""
    path = Path(name)
    if path.suffix in (".yaml", ".yml") or path.exists():
        return path
    for folder in search_folders():
        candidate = folder / f"{name}.yaml"
        if candidate.is_file():
            return candidate
    near = sorted({p.stem for folder in search_folders() for p in folder.glob("*.yaml")})
    raise UsageError.single(f"no bus config for robot '{name}'{did_you_mean(name, near)}",
                            hint="give a bus config path, or a robot's name: NAME.yaml here, "
                                 f"in ./bus_config/ or one hil ships ({shipped_names()})")
