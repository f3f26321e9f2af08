"""Where a bus config is: a path, or a robot's name."""

from __future__ import annotations

from pathlib import Path

from hil.errors import HilError
from hil.resources import BUS_CONFIGS, data_dir


def config_path(name: str) -> Path:
    """A bus config: a path, or a robot's name (bus_config/<name>.yaml here, else the one
    hil ships)."""
    path = Path(name)
    if path.suffix in (".yaml", ".yml") or path.exists():
        return path
    for folder in (Path("bus_config"), data_dir(BUS_CONFIGS)):
        candidate = folder / f"{name}.yaml"
        if candidate.is_file():
            return candidate
    shipped = sorted(p.stem for p in data_dir(BUS_CONFIGS).glob("*.yaml"))
    raise HilError.single(f"no bus config for robot '{name}'",
                          hint=f"give a bus config path, or one of: {', '.join(shipped)}")
