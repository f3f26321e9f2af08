"""A robot's recorder as a bus config describes it: what ``hil viz`` records of each robot
and what hil's pytest plugin keeps of a ``hil_stack`` run, one recorder for both."""

from __future__ import annotations

from pathlib import Path

import rerun as rr

from hil.bus_config import SystemConfig
from hil.file_names import file_stem
from hil.messaging.keys import IMU, WRENCH
from hil.visualisation.recorder import BenchParts, RunRecorder
from hil.visualisation.urdf_export import viewer_urdf


def config_recorder(recording: rr.RecordingStream, config: SystemConfig, folder: Path,
                    namespaced: bool) -> RunRecorder:
    """A recorder of ``config``'s robot on ``recording`` (its viewer URDF written to
    ``folder``); ``namespaced``: one of several robots (RunRecorder)."""
    urdf = folder / f"{file_stem(config.robot.name)}.urdf"    # a name over NAME_MAX: cut
    urdf.write_bytes(viewer_urdf(config.robot))
    parts = BenchParts(config.scene, {d.actuator: d.peak_torque for d in config.drives},
                       config.floating_base, {b.name: b.load().worst_ratio for b in config.buses},
                       tuple((s.name, IMU) for s in config.imus)
                       + tuple((s.name, WRENCH) for s in config.force_torques))
    return RunRecorder(recording, config.robot, urdf, actuator_joints(config),
                       tuple(b.name for b in config.buses), namespaced, parts)


def actuator_joints(config: SystemConfig) -> dict[str, tuple[str, ...]]:
    """Each actuator's joints, by its transmission."""
    return {a.name: tuple(tj.name for tj in t.joints)
            for t in config.robot.transmissions for a in t.actuators}
