"""What a ``hil_stack`` test keeps of its run, as ``hil up`` keeps a run's: every CAN frame
in one BLF (``run.can.blf``, channels numbered in the config's bus order: ``hil replay``
maps them by itself) from the stack's first frame, and the controller's cycles, faults and
resets in a rerun recording (``run.rrd``: ``hil review`` reads it) from the first cycle the
recorder hears (the stack starts it once the controller cycles)."""

from __future__ import annotations

import threading
import uuid
from pathlib import Path

from hil.bus_config import SystemConfig, open_buses
from hil.can.monitor import BusMonitor
from hil.stack import IN_PROCESS, Stack
from hil.zenoh_session import ZenohSettings


class StackRecording:
    """A stack's run kept in ``folder``: its buses logged from before it starts
    (:attr:`channels` are the ones to start it on), its cycles recorded once :meth:`record`
    is given it; :meth:`close` writes both whole."""

    def __init__(self, config: SystemConfig, folder: Path):
        folder.mkdir(parents=True, exist_ok=True)
        self.config = config
        self.folder = folder
        tag = uuid.uuid4().hex[:8]
        #: bus name -> the in-process channel the stack is to use
        self.channels = {b.name: f"hil-stack-{tag}-{b.name}" for b in config.buses}
        self.can_log = folder / "run.can.blf"
        self.recording_path = folder / "run.rrd"
        buses = open_buses(config, ZenohSettings.meeting(), IN_PROCESS, self.channels,
                           logging=True)
        self._monitor = BusMonitor(buses, self.channels,
                                   {b.name: b.bit_rates for b in config.buses}, self.can_log)
        self._recorded: tuple | None = None

    def record(self, stack: Stack) -> None:
        """Record the stack's cycles, faults and resets from now (as ``hil viz`` does)."""
        import rerun as rr                                  # noqa: PLC0415 (rerun: heavy)

        from hil.visualisation.blueprint import run_blueprint  # noqa: PLC0415
        from hil.visualisation.node import VizNode              # noqa: PLC0415
        from hil.visualisation.of_config import config_recorder  # noqa: PLC0415

        recording = rr.RecordingStream("hil", recording_id=f"{self.config.robot.name}-test")
        recording.save(str(self.recording_path))
        recorder = config_recorder(recording, self.config, self.folder, namespaced=False)
        recorder.log_static()
        recording.send_blueprint(run_blueprint([recorder.view()],
                                               lock_step=stack.sim.lock_step))
        node = VizNode([recorder], stack.zenoh)
        thread = threading.Thread(target=node.run, name="hil-test-recording", daemon=True)
        thread.start()
        self._recorded = (recording, recorder, node, thread)

    def stop_recording(self) -> None:
        """The recorder stopped and its file written whole (before the stack closes its
        Zenoh session, which the recorder hears through)."""
        if self._recorded is None:
            return
        recording, recorder, node, thread = self._recorded
        self._recorded = None
        node.stop()
        thread.join(10)
        recorder.flush()
        recording.flush()
        recording.disconnect()

    def close(self) -> None:
        """Recorder and CAN log closed, each file written whole (idempotent)."""
        self.stop_recording()
        if self._monitor is not None:
            self._monitor.close()
            self._monitor = None
