"""hil's pytest plugin (entry point ``pytest11``: pytest loads it wherever hil is installed).

Fixtures, each a factory whose products are closed when the test ends:

* ``hil_drives(config, lock_step=False, vcan=None)``: a
  :class:`~hil.testing.drives.DrivesBench` (the config's drives and plant, a python-can bus
  per CAN bus for your master; ``vcan={"arm": "vcan0"}``: on SocketCAN interfaces);
* ``hil_stack(config, lock_step=True)``: hil's whole stack in the test's process
  (:class:`hil.stack.Stack`: drives, plant, hil's master and controllers, the joint
  trajectory action on ``stack.zenoh``).

Every bus of a drives bench is logged, frame by frame, to a BLF file in the test's
``tmp_path``; a failed test's report lists the logs it kept ("hil artefacts"), and so does
its JUnit entry (``--junitxml``: a property ``hil_can_log`` per bus). Importing this module
loads nothing of hil's: the fixtures import what they start.
"""

from __future__ import annotations

from pathlib import Path

import pytest

#: the files a test's hil fixtures kept, for its report
ARTEFACTS = pytest.StashKey[list]()


@pytest.fixture
def hil_drives(request, tmp_path):
    """A factory of drives-only benches: ``hil_drives("ur3", lock_step=True)``."""
    from hil.testing.drives import DrivesBench

    opened = []

    def make(config, *, lock_step: bool = False, package_path=None, vcan=None) -> DrivesBench:
        bench = DrivesBench(config, lock_step=lock_step, package_path=package_path, vcan=vcan)
        opened.append(bench)
        folder = tmp_path / f"hil-can-{len(opened)}"
        for path in bench.log_to(folder):
            request.node.stash.setdefault(ARTEFACTS, []).append(path)
            request.node.user_properties.append(("hil_can_log", str(path)))
        return bench

    yield make
    for bench in opened:
        bench.close()


@pytest.fixture
def hil_stack():
    """A factory of whole stacks: ``hil_stack("ur3")`` (lock-step unless told otherwise)."""
    from contextlib import ExitStack

    from hil.bus_config import config_path, load_bus_config
    from hil.realtime import LOCK_STEP, REAL_TIME
    from hil.stack import running_stack

    with ExitStack() as started:
        def make(config, *, lock_step: bool = True, package_path=None):
            loaded = load_bus_config(config_path(str(config)), package_path)
            return started.enter_context(running_stack(loaded, LOCK_STEP if lock_step
                                                       else REAL_TIME))
        yield make


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    kept: list[Path] = item.stash.get(ARTEFACTS, [])
    if report.failed and kept:
        report.sections.append(("hil artefacts", "\n".join(f"kept: {path}" for path in kept)))
