"""hil's pytest plugin (entry point ``pytest11``: pytest loads it wherever hil is installed).

Fixtures, each a factory whose products are closed when the test ends:

* ``hil_drives(config, lock_step=False, vcan=None)``: a
  :class:`~hil.testing.drives.DrivesBench` (the config's drives and plant, a python-can bus
  per CAN bus for your master; ``vcan={"arm": "vcan0"}``: on SocketCAN interfaces);
* ``hil_stack(config, lock_step=True)``: hil's whole stack in the test's process
  (:class:`hil.stack.Stack`: drives, plant, hil's master and controllers, the joint
  trajectory action on ``stack.zenoh``).

What a test's run leaves goes to its ``tmp_path``, as ``hil up`` leaves a run's: every bus
of a drives bench logged, frame by frame, to a BLF file per bus (``hil-can-N/BUS.blf``:
``hil replay hil-can-N CONFIG`` reads the folder; a bus' name too long for a file's is cut
and a hash of it added, :mod:`hil.file_names`); of a whole stack, every bus to one BLF
and the controller's cycles, faults and resets to a rerun recording
(``hil-stack-N/run.can.blf`` for ``hil replay``, ``run.rrd`` for ``hil review``;
:mod:`hil.testing.recording`). A failed test's report lists them ("hil artefacts"), each
with the command that reads it, and so does its JUnit entry (``--junitxml``: a property
``hil_can_log`` per CAN log, ``hil_recording`` per recording). Importing this module loads
nothing of hil's: the fixtures import what they start.
"""

from __future__ import annotations

from pathlib import Path

import pytest

#: what a test's hil fixtures kept, for its report: lines naming each file and its reader
ARTEFACTS = pytest.StashKey[list]()


def _keep(request, path: Path, reader: str, junit: str | None = None) -> None:
    """``path`` listed in the test's report if it fails (``reader``: the command that reads
    it), and as a JUnit property ``junit``."""
    request.node.stash.setdefault(ARTEFACTS, []).append(f"kept: {path}  ({reader})")
    if junit is not None:
        request.node.user_properties.append((junit, str(path)))


@pytest.fixture
def hil_drives(request, tmp_path):
    """A factory of drives-only benches: ``hil_drives("ur3", lock_step=True)``."""
    from hil.testing.drives import DrivesBench

    opened = []

    def make(config, *, lock_step: bool = False, package_path=None, vcan=None) -> DrivesBench:
        bench = DrivesBench(config, lock_step=lock_step, package_path=package_path, vcan=vcan)
        opened.append(bench)
        folder = tmp_path / f"hil-can-{len(opened)}"
        replay = f"hil replay {folder} {bench.config.path}"
        for path in bench.log_to(folder):
            _keep(request, path, f"all buses: {replay}", "hil_can_log")
        return bench

    yield make
    for bench in opened:
        bench.close()


@pytest.fixture
def hil_stack(request, tmp_path):
    """A factory of whole stacks: ``hil_stack("ur3")`` (lock-step unless told otherwise)."""
    from contextlib import ExitStack

    from hil.bus_config import config_path, load_bus_config
    from hil.realtime import LOCK_STEP, REAL_TIME
    from hil.stack import running_stack
    from hil.testing.recording import StackRecording

    made = []
    with ExitStack() as started:
        def make(config, *, lock_step: bool = True, package_path=None):
            loaded = load_bus_config(config_path(str(config)), package_path)
            made.append(loaded)
            kept = StackRecording(loaded, tmp_path / f"hil-stack-{len(made)}")
            started.callback(kept.close)            # last: the stack's final frames logged
            _keep(request, kept.recording_path, f"hil review {kept.recording_path}",
                  "hil_recording")
            _keep(request, kept.can_log, f"hil replay {kept.can_log} {loaded.path}",
                  "hil_can_log")
            stack = started.enter_context(running_stack(
                loaded, LOCK_STEP if lock_step else REAL_TIME, channels=kept.channels))
            started.callback(kept.stop_recording)   # first: before the stack's session closes
            kept.record(stack)
            return stack
        yield make


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    kept: list[str] = item.stash.get(ARTEFACTS, [])
    if report.failed and kept:
        report.sections.append(("hil artefacts", "\n".join(kept)))
