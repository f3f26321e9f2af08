"""hil as a package: what the controller process loads, and protocols from other packages."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap

from conftest import ROOT

#: a drive protocol from outside hil: a module and its .dist-info (entry point group
#: hil.protocols), exactly as pip leaves an installed package
TOY_PACKAGE = ROOT / "tests" / "fixtures" / "toy_protocol"

#: modules of the simulated side, which the controller process must never load (MuJoCo: but
#: for a drive's gravity feed-forward, whose model of the description it computes with,
#: hil.hardware.gravity; the configs below ask none)
DRIVE_SIDE = ("hil.drives", "hil.simulator", "hil.plant", "hil.protocols.cia402.node",
              "hil.protocols.cia402.state", "mujoco")


def python(script: str, *, env: dict | None = None, timeout: float = 120
           ) -> tuple[subprocess.CompletedProcess, set[str]]:
    """Run ``script`` under ``python -X importtime``; the run, and every module it imported:
    those importtime reported (``import`` statements) and those in sys.modules at the end
    (importtime does not see importlib.import_module, which hil uses for protocols)."""
    script = textwrap.dedent(script) + "\nimport sys\nprint(*sys.modules, file=sys.stderr)\n"
    done = subprocess.run([sys.executable, "-X", "importtime", "-c", script],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT,
                          env={**os.environ, **(env or {})})
    lines = done.stderr.splitlines()
    modules = {line.rsplit("|", 1)[1].strip() for line in lines
               if line.startswith("import time:") and "|" in line}
    if done.returncode == 0:
        modules |= set(lines[-1].split())
    return done, modules - {"imported package"}


def _drive_side(modules: set[str]) -> list[str]:
    return sorted(m for m in modules if m.startswith(DRIVE_SIDE) or m.endswith(".drive"))


def test_importing_the_controller_entry_module_loads_no_drive_side_module_and_no_canopen():
    done, modules = python("import hil.cli.control")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "hil.control_node" in modules and "hil.hardware.interface" in modules
    assert _drive_side(modules) == []
    assert sorted(m for m in modules if m.split(".")[0] == "canopen") == []


def test_the_running_controller_loads_no_simulated_drive_module_and_makes_no_local_node():
    # at run time every protocol's master-side axis for every shipped bus config
    # (CanHardwareInterface imports them on construction, canopen with the first bus)
    done, modules = python("""
        import gc
        import can
        import canopen
        import hil.cli.control
        from hil.bus_config import load_bus_config
        from hil.hardware import CanHardwareInterface
        for name in ("ur3", "pigot", "pigot_mixed"):
            config = load_bus_config(f"bus_config/{name}.yaml")
            buses = {b.name: can.Bus(interface="virtual", channel=f"package-{name}-{b.name}")
                     for b in config.buses}
            CanHardwareInterface(config, buses)
            local = [o for o in gc.get_objects() if issubclass(type(o), canopen.LocalNode)]
            print("local nodes:", len(local))
            for bus in buses.values():
                bus.shutdown()
        """)
    assert done.returncode == 0, done.stderr[-3000:]
    assert {"hil.protocols.cia402.axis", "hil.protocols.odrive.axis",
            "hil.protocols.mit.axis"} <= modules           # the check saw every protocol
    assert _drive_side(modules) == []
    # canopen.node.local is loaded here (canopen's own __init__ imports it with the master's
    # RemoteNode and Network); the master never makes a LocalNode
    assert done.stdout.count("local nodes: 0") == 3, done.stdout


def test_a_protocol_from_an_installed_package_drives_a_joint(tmp_path):
    config = tmp_path / "ur3_toy.yaml"
    config.write_text(textwrap.dedent(f"""\
        robot: {ROOT / 'robots' / 'ur3_description' / 'urdf' / 'ur3.xacro'}
        plant_rate_hz: 1000
        defaults: {{protocol: toy, watchdog_timeout: 0.2}}
        buses:
          - name: arm
            interface: virtual
            channel: hil-package-toy
            bitrate: 1000000
            fd: true
            cycle_hz: 100
            drives: [{{node_id: 1, joint: joint1}}, {{node_id: 2, joint: joint2}},
                     {{node_id: 3, joint: joint3}}, {{node_id: 4, joint: joint4}},
                     {{node_id: 5, joint: joint5}}, {{node_id: 6, joint: joint6}}]
        """))
    unregistered = subprocess.run([sys.executable, "-m", "hil", "check", str(config)],
                                  capture_output=True, text=True, timeout=60)
    assert unregistered.returncode == 1 and "toy" in unregistered.stderr
    assert "Traceback" not in unregistered.stderr
    done, modules = python(f"""
        from hil.bus_config import load_bus_config
        from hil.controllers import TrajectoryGoal, TrajectoryPoint
        from hil.messaging.zenoh_api import TrajectoryActionClient
        from hil.realtime import LOCK_STEP
        from hil.stack import running_stack

        config = load_bus_config({str(config)!r})
        with running_stack(config, LOCK_STEP) as stack:    # what it moves, not how fast
            client = TrajectoryActionClient(stack.zenoh, config.robot.name)
            goal = TrajectoryGoal(("joint2",), (TrajectoryPoint(1.0, (0.3,), (0.0,)),))
            result = client.wait_result(client.send_goal(goal), timeout=60)
            print(result.error_code, stack.sim.plant.joint_positions()[1], flush=True)
            client.close()
        """, env={"PYTHONPATH": str(TOY_PACKAGE)})
    assert done.returncode == 0, done.stderr[-3000:]
    assert "hil_toy_protocol.drive" in modules
    error_code, joint2 = done.stdout.split()
    assert int(error_code) == 0
    assert abs(float(joint2) - 0.3) < 0.01


#: import-linter's command, installed beside this interpreter (the test extra)
LINT_IMPORTS = os.path.join(os.path.dirname(sys.executable), "lint-imports")


def lint_imports(package_root, *contracts: str) -> subprocess.CompletedProcess:
    """import-linter over the ``hil`` package found at ``package_root``, with the contracts
    of this repository's pyproject.toml."""
    argv = [LINT_IMPORTS, "--no-cache", "--no-logo", str(ROOT / "pyproject.toml")]
    for contract in contracts:
        argv += ["--contract", contract]
    return subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=package_root,
                          env={**os.environ, "PYTHONPATH": str(package_root)})


def planted(tmp_path, module: str, line: str):
    """A copy of the ``hil`` package in ``tmp_path``, ``line`` added to ``module``'s file
    (a path under hil/); where to run :func:`lint_imports` on it."""
    shutil.copytree(ROOT / "hil", tmp_path / "hil",
                    ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.sha256"))
    source = tmp_path / "hil" / module
    source.write_text(source.read_text() + f"\n{line}\n")
    return tmp_path


def test_the_package_keeps_its_import_contracts():
    done = lint_imports(ROOT)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
    assert "5 kept, 0 broken" in done.stdout, done.stdout[-2000:]


def test_an_upward_import_breaks_the_stages_contract(tmp_path):
    # the same package with one planted import of the command line into the CAN plumbing
    done = lint_imports(planted(tmp_path, "can/frames.py", "import hil.cli.up"), "stages")
    assert done.returncode == 1
    assert "hil.can is not allowed to import hil.cli" in done.stdout, done.stdout[-2000:]
    assert "hil.can.frames -> hil.cli.up" in done.stdout


def test_two_files_of_a_package_that_import_each_other_break_the_no_circles_contract(tmp_path):
    # the Zenoh bus builds on its session's channels: the channels importing the bus back
    # (even for type checking alone, which import-linter counts) closes a circle
    done = lint_imports(planted(tmp_path, "can/zenoh_channels.py", "import hil.can.zenoh_bus"),
                        "no-circles")
    assert done.returncode == 1
    assert "No cycles are allowed in hil.can" in done.stdout, done.stdout[-2000:]


def test_a_master_side_axis_that_reaches_a_simulated_drive_breaks_its_contract(tmp_path):
    done = lint_imports(planted(tmp_path, "protocols/odrive/axis.py",
                                "import hil.protocols.odrive.drive"), "controller-side")
    assert done.returncode == 1
    assert "hil.protocols.odrive.axis -> hil.protocols.odrive.drive" in done.stdout, \
        done.stdout[-2000:]


def test_a_protocol_module_the_drive_core_imports_past_the_seam_breaks_its_contract(tmp_path):
    # the drive core is protocol-free (docs/design.md, "Layout"): it knows a protocol as
    # hil.protocols.base's Protocol, never one protocol's own modules
    done = lint_imports(planted(tmp_path, "drives/core.py", "import hil.protocols.odrive.sdo"),
                        "protocol-seams")
    assert done.returncode == 1
    assert "hil.drives.core -> hil.protocols.odrive.sdo" in done.stdout, done.stdout[-2000:]


def test_the_bench_loads_no_command_line_module():
    done, modules = python("import hil.bench")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "hil.bench.processes" in modules and "hil.supervisor" in modules
    assert sorted(m for m in modules if m.startswith("hil.cli")) == []


def test_the_hardware_interface_loads_no_yaml_parser_and_no_description_reader():
    done, modules = python("import hil.hardware")
    assert done.returncode == 0, done.stderr[-3000:]
    assert "hil.hardware.interface" in modules and "hil.bus_config.types" in modules
    readers = ("yaml", "xacro", "hil.bus_config.parse", "hil.bus_config.yaml_reader",
               "hil.description.reader", "hil.description.urdf", "hil.description.source")
    assert sorted(m for m in modules if m.startswith(readers)) == []


def test_every_module_named_by_a_string_lies_where_a_plain_import_of_it_would_be_allowed():
    """import-linter sees no import by string: the three places that load by name stay within
    what the contracts allow a plain import. A package's lazy exports name its own modules;
    a protocol's drive and axis lie in its own folder, on the side the contracts give them
    (``hil.protocols.*.drive`` the drives', ``hil.protocols.*.axis`` the master's); the
    commands are ``hil.cli``'s own."""
    import ast

    from hil.cli import COMMANDS
    from hil.protocols import BUILTIN, protocol

    for init in sorted((ROOT / "hil").rglob("__init__.py")):
        package = ".".join(init.relative_to(ROOT).parent.parts)
        for call in ast.walk(ast.parse(init.read_text())):
            if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "lazy_exports":
                modules = [value.value for value in call.args[1].values]
                assert modules and all(m.startswith(package + ".") for m in modules), init
    for name in BUILTIN:
        family = protocol(name)
        folder = f"hil.protocols.{name}."
        assert family.drive.partition(":")[0] == folder + "drive", name
        assert family.axis.partition(":")[0] == folder + "axis", name
    assert COMMANDS and all("." not in command for command in COMMANDS)
