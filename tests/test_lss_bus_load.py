"""The bus-load check of drives that boot without a node id (CiA 305 LSS, node id 255): no
crash, and each counted with the exchange it has once a master assigned its id (issue 65,
item 6: a bus of only such drives, the shape of docs/protocols/cia402.md's own example, made
`hil check` fail with ZeroDivisionError)."""

from __future__ import annotations

from hil.bus_config import load_bus_config
from hil.cli import main
from conftest import ROOT

UR3 = ROOT / "robots/ur3_description/urdf/ur3.xacro"


def lss_config(tmp_path, node_ids, cycle_hz=500):
    drives = "".join(f"      - {{node_id: {node_id}, joint: joint{i}, "
                     f"options: {{serial_number: {1000 + i}}}}}\n"
                     for i, node_id in enumerate(node_ids, start=1))
    path = tmp_path / "lss.yaml"
    path.write_text(f"robot: {UR3}\nbuses:\n  - name: arm\n    interface: virtual\n"
                    f"    channel: test\n    bitrate: 1000000\n    cycle_hz: {cycle_hz}\n"
                    f"    drives:\n{drives}")
    return path


def test_a_bus_of_drives_awaiting_lss_checks_without_a_traceback(tmp_path, capsys):
    assert main(["check", str(lss_config(tmp_path, [255] * 6, cycle_hz=250))]) == 0
    assert "6 drive(s); load 54% worst case" in capsys.readouterr().out


def test_drives_awaiting_lss_load_the_bus_as_they_will_once_assigned(tmp_path):
    waiting = load_bus_config(lss_config(tmp_path, [255] * 6, cycle_hz=250)).buses[0].load()
    assigned = load_bus_config(lss_config(tmp_path, range(1, 7), cycle_hz=250)).buses[0].load()
    assert waiting == assigned


def test_too_many_drives_awaiting_lss_are_refused_with_a_split_hint(tmp_path, capsys):
    assert main(["check", str(lss_config(tmp_path, [255] * 6, cycle_hz=1000))]) != 0
    err = capsys.readouterr().err
    assert "infeasible" in err and "split the drives over buses of at most" in err
