#!/usr/bin/env python3
"""What a sensor costs the simulator: plant steps a second of the ur3 with no sensor, with
a WitMotion IMU at 200 Hz (to a capture) and with a HiPNUC IMU at 100 Hz (to a capture), each
stepped as the simulator steps it (hil.simulator.stepping.PlantStepping, no drive), in turns,
ROUNDS times; the median of each and the overhead per plant step (docs/performance.md).

    .venv/bin/python tools/sensor_cost.py [STEPS]
"""

from __future__ import annotations

import functools
import statistics
import sys
import tempfile
import time
from pathlib import Path

import yaml

from hil.bus_config import load_bus_config
from hil.sensors.imu import SimulatedImu
from hil.simulator.build import bench_plant
from hil.simulator.stepping import PlantStepping

ROOT = Path(__file__).resolve().parents[1]
ROUNDS = 7
SENSORS = {
    "none": None,
    "wit 200 Hz": {"name": "imu", "product": "wit", "link": "link6", "port": "imu",
                   "baud": 460800, "rate_hz": 200},
    "hipnuc 100 Hz": {"name": "imu", "product": "hipnuc", "link": "link6", "bus": "wrist",
                      "node_id": 8, "rate_hz": 100},
}


class Capture:
    device = "capture"

    def write(self, data) -> None:
        pass

    def close(self) -> None:
        pass


def stepping(folder: Path, sensor: dict | None) -> PlantStepping:
    config = yaml.safe_load((ROOT / "bus_config" / "ur3.yaml").read_text())
    config["robot"] = str((ROOT / "bus_config" / config["robot"]).resolve())
    if sensor is not None:
        config["sensors"] = [sensor]
    path = folder / "ur3.yaml"
    path.write_text(yaml.safe_dump(config))
    loaded = load_bus_config(path)
    plant = bench_plant(loaded)
    steps = PlantStepping(plant)
    for imu in loaded.imus:
        steps.sensors.append(SimulatedImu(imu, functools.partial(plant.sensors.read, imu.name),
                                          Capture()))
    return steps


def main() -> int:
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
    with tempfile.TemporaryDirectory() as folder:
        benches = {name: stepping(Path(folder), sensor) for name, sensor in SENSORS.items()}
        times: dict[str, list[float]] = {name: [] for name in benches}
        for _ in range(ROUNDS):
            for name, bench in benches.items():
                begun = time.perf_counter()
                for _ in range(count):
                    bench.step()
                times[name].append((time.perf_counter() - begun) / count)
    base = statistics.median(times["none"])
    for name, measured in times.items():
        median = statistics.median(measured)
        print(f"{name:14s} {median * 1e6:7.2f} us a plant step (min {min(measured) * 1e6:.2f}, "
              f"max {max(measured) * 1e6:.2f}); +{(median - base) * 1e6:.2f} us")
    return 0


if __name__ == "__main__":
    sys.exit(main())
