"""Testing the user's own master and controllers with hil, in pytest.

:class:`~hil.testing.drives.DrivesBench`: a config's simulated drives and plant in the
test's process, a python-can bus per CAN bus for the master under test. The pytest plugin
(:mod:`hil.testing.pytest_plugin`, loaded by pytest wherever hil is installed) gives
fixtures for it and for hil's whole stack, and keeps a failed test's CAN logs. The guide:
docs/testing.md.
"""

from hil.lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {"DrivesBench": "hil.testing.drives",
                                      "DriveInfo": "hil.testing.drives"})

__all__ = ["DriveInfo", "DrivesBench"]
