"""The data hil ships: robot descriptions, bus configs, the CiA 402 drives' and the HiPNUC
IMU's EDS.

They live in the repository's ``robots/`` and ``bus_config/`` folders; a wheel carries them
inside the package (``hil/data/``, copied there by the build: setup.py). :func:`data_dir`
finds them either way, so that ``hil up pigot`` works from any folder after ``pip install``.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from hil.errors import HilError

#: the folders the package ships
ROBOTS, BUS_CONFIGS = "robots", "bus_config"


def data_dir(name: str) -> Path:
    """The folder ``name`` (:data:`ROBOTS`, :data:`BUS_CONFIGS`) of this installation."""
    bundled = Path(str(files("hil"))) / "data" / name           # a wheel's
    if bundled.is_dir():
        return bundled
    checkout = Path(__file__).resolve().parents[1] / name        # a checkout's (editable)
    if checkout.is_dir():
        return checkout
    raise HilError.single(f"this hil installation has no '{name}' folder (looked in "
                          f"{bundled} and {checkout})",
                          hint="reinstall hil: pip install --force-reinstall hil")


def eds_path() -> Path:
    """The EDS of hil's virtual CiA 402 drive (written by tools/make_cia402_eds.py)."""
    return data_dir(BUS_CONFIGS) / "cia402_drive.eds"


def hipnuc_eds_path() -> Path:
    """The EDS of a HiPNUC IMU in its CANopen mode as hil serves it (written by
    tools/make_hipnuc_eds.py)."""
    return data_dir(BUS_CONFIGS) / "hipnuc_imu.eds"
