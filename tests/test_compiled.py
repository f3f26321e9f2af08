"""Compiled modules (setup.py compiles them with mypyc): never stale, and telling which runs."""

from __future__ import annotations

import hashlib
import math
import importlib.machinery
import importlib.util
import os
import sys
from pathlib import Path

import grimp
import pytest

import hil.can.link_account
import hil.can.zenoh_wire
import hil.drives.core
import hil.hardware
import hil.protocols.mit.codec
from hil.can.frame import Frame
from hil.compiled import BUILDS, import_fresh, is_compiled
from conftest import TEST_MOTOR_DRIVE

SUFFIX = importlib.machinery.EXTENSION_SUFFIXES[0]


@pytest.fixture
def package(tmp_path, monkeypatch):
    """An importable package 'stalepkg' in tmp_path; its modules leave sys.modules after."""
    (tmp_path / "stalepkg").mkdir()
    (tmp_path / "stalepkg" / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path / "stalepkg"
    for name in [n for n in sys.modules if n.split(".")[0] == "stalepkg"]:
        del sys.modules[name]


def _write(package, name: str, edited: bool) -> None:
    """Module ``name`` as source and as a (broken) compiled form, with the build's record of
    the source it compiled: this source, or one edited since."""
    (package / f"{name}{SUFFIX}").write_bytes(b"not a shared object: importing it fails")
    source = f"NAME = '{name}'\n"
    (package / f"{name}.py").write_text(source)
    compiled_from = source + ("# before the edit\n" if edited else "")
    (package / f"{name}.sha256").write_text(hashlib.sha256(compiled_from.encode()).hexdigest())


def test_compiled_modules_give_way_to_their_sources_after_an_edit_to_either(package):
    _write(package, "core", edited=False)
    _write(package, "state", edited=True)
    with pytest.warns(UserWarning, match=r"state\.py changed since compiled"):
        import_fresh("stalepkg.core", "stalepkg.state")
    for name in ("core", "state"):             # not mixed: both run from their sources
        module = sys.modules[f"stalepkg.{name}"]
        assert module.NAME == name and not is_compiled(module)
        assert getattr(sys.modules["stalepkg"], name) is module


def test_compiled_modules_of_unchanged_sources_are_the_ones_imported(package):
    _write(package, "core", edited=False)
    os.utime(package / "core.py")           # touched, not changed: the record is what counts
    with pytest.raises(ImportError):        # the (broken) compiled form is what loads
        import_fresh("stalepkg.core")
    assert "stalepkg.core" not in sys.modules


def _torques(core_module, velocity_mode: bool) -> list[tuple]:
    """One drive core's torques and status through enable, moves, a quick stop and a fault
    (position mode: a following error), on a bare motor shaft (J = 1e-3 kg m^2)."""
    core = core_module.DriveCore(core_module.DriveParameters(**TEST_MOTOR_DRIVE))
    core.set_cycle(0.01)
    core.enable()
    if velocity_mode:
        core.set_mode(core_module.Mode.VELOCITY)
    position = velocity = 0.0
    seen = []
    for k in range(1500):
        if k % 10 == 0:
            core.new_setpoint(position=0.03 * k if k < 600 else 60.0, velocity=5.0, now=0.0,
                              torque_ff=0.01)
        if k == 1000:
            core.quick_stop()
        if k == 1200:                            # position mode has faulted on its own by now
            core.raise_fault(core_module.Fault.EMERGENCY_STOP)
        core.measure(position, velocity)
        torque = core.update(0.001)
        velocity += torque / 1e-3 * 0.001
        position += velocity * 0.001
        status = core.status()
        seen.append((torque, status.power.value, status.following_error, status.target_reached,
                     status.fault.value if status.fault else None))
    return seen


@pytest.mark.skipif(not is_compiled(hil.drives.core),
                    reason="the drive core is not compiled in this install (setup.py found no "
                           "C compiler, or a module it compiles (hil.compiled.COMPILED) changed "
                           "since `pip install -e .`)")
@pytest.mark.parametrize("velocity_mode", [False, True])
def test_the_compiled_drive_core_computes_what_its_source_does(velocity_mode):
    source = _source_of(hil.drives.core)
    interpreted = _torques(source, velocity_mode)
    compiled = _torques(hil.drives.core, velocity_mode)
    assert not is_compiled(source)
    assert compiled == interpreted                   # bit for bit: the same float operations
    assert any(fault for *_, fault in compiled)      # the run reached the fault


@pytest.mark.parametrize("build", list(BUILDS))
def test_the_modules_of_a_build_load_all_compiled_or_none(build):
    # compiled modules of one build call each other's classes directly (hil.compiled)
    forms = {name: is_compiled(sys.modules[name]) for name in BUILDS[build]}
    assert len(set(forms.values())) == 1, forms


@pytest.mark.skipif(not is_compiled(hil.protocols.mit.codec),
                    reason="the MIT codec is not compiled in this install (setup.py found no C "
                           "compiler, or hil/protocols/mit/codec.py changed since "
                           "`pip install -e .`)")
def test_the_compiled_mit_codec_packs_and_unpacks_what_its_source_does():
    source = _source_of(hil.protocols.mit.codec)
    compiled = hil.protocols.mit.codec
    assert not is_compiled(source)
    ranges = (12.5, 30.0, 500.0, 5.0, 10.0)
    edges = [math.inf, -math.inf, 1e308, -0.0, 12.5, -12.5, 40.0, 0.1]
    values = edges + [math.sin(1.3 * k) * 14.0 for k in range(300)]
    for k, value in enumerate(values):
        command = (value, values[k - 1], abs(values[k - 2]) * 40, abs(value) / 3, -value)
        packed = compiled.pack_command(compiled.MitCommand(*command), compiled.MitRanges(*ranges))
        assert packed == source.pack_command(source.MitCommand(*command),
                                             source.MitRanges(*ranges))
        assert compiled.unpack_command(packed, compiled.MitRanges(*ranges)) == \
            source.unpack_command(packed, source.MitRanges(*ranges))   # bit for bit
        assert compiled.pack_motion(value, -value, value / 2, compiled.MitRanges(*ranges)) == \
            source.pack_motion(value, -value, value / 2, source.MitRanges(*ranges))
        assert compiled.pack_answer(k & 0xFF, value, -value, value / 2,
                                    compiled.MitRanges(*ranges), b"\x19\x1a") == \
            source.pack_answer(k & 0xFF, value, -value, value / 2, source.MitRanges(*ranges),
                               b"\x19\x1a")
    for module in (compiled, source):           # NaN: refused alike, never packed
        with pytest.raises(ValueError, match="NaN"):
            module.float_to_uint(math.nan, -1.0, 1.0, 16)


@pytest.mark.skipif(not is_compiled(hil.can.zenoh_wire),
                    reason="the Zenoh transport is not compiled in this install (setup.py found "
                           "no C compiler, or a module of hil.compiled.COMPILED_TRANSPORT "
                           "changed since `pip install -e .`)")
def test_the_compiled_transport_encodes_decodes_and_counts_what_its_source_does():
    wire, account = _source_of(hil.can.zenoh_wire), _source_of(hil.can.link_account)
    assert not is_compiled(wire) and not is_compiled(account)
    frames = [Frame(0x123, bytes(range(8))), Frame(0x1ABCDEF0, b"\x01", extended=True),
              Frame(0x7FF, bytes(3), remote=True), Frame(0x80),
              Frame(0x201, bytes(range(64)), fd=True, bitrate_switch=True),
              Frame(0x0, bytes(8), error=True)]
    sides = [(hil.can.zenoh_wire, hil.can.link_account.LinkAccount(7, "bus")),
             (wire, account.LinkAccount(7, "bus"))]
    seen = []
    for codec, link in sides:
        payloads, counted = [], []
        for k in range(40):        # a gap, a late message, echoes of its own puts
            echo = link.sent(1 + 6 * k, len(frames), 100.0 + 0.002 * k)
            payload = codec.encode_frames("g1/bus1", 99, 1 + 6 * k, 1e9 + k, frames, echo)
            payloads.append(payload)
            first = 1 + 6 * (k if k % 7 else k + 1)
            message = codec.Message("g1/bus1", 5, first, 1e9 + k,
                                    codec.Echo(7, 1 + 6 * k, 0.0005), frames)
            counted.append(link.arrived(message, 1e9 + k + 0.001 * (k % 3),
                                        100.0 + 0.002 * k + 0.0003))
            payloads.append(codec.decode_frames(payload + payload))
        refusals = []
        for bad in (b"", b"\x03ab", payloads[0][:-3], payloads[0][:60] + b"\xff" * 9):
            with pytest.raises(ValueError) as refused:
                codec.decode_frames(bad)
            refusals.append(str(refused.value))
        counters = link.counters
        seen.append((payloads, counted, refusals, str(counters), link.heard(),
                     counters.round_trip, counters.lost, counters.late))
    assert seen[0] == seen[1]                  # bit for bit
    assert seen[0][-2] > 0                     # the gaps counted


def _source_of(module):
    """``module`` run from its Python source, beside its compiled form (not in sys.modules
    once loaded: dataclasses look their module up while the class is made)."""
    name = f"{module.__name__.replace('.', '_')}_source"
    path = Path(module.__file__).with_name(module.__name__.rpartition(".")[2] + ".py")
    spec = importlib.util.spec_from_file_location(name, path)
    source = importlib.util.module_from_spec(spec)
    sys.modules[name] = source
    try:
        spec.loader.exec_module(source)
    finally:
        del sys.modules[name]
    return source


@pytest.mark.parametrize("loader", ["hil.drives", "hil.hardware"])
def test_each_module_of_a_build_outside_its_package_is_an_import_the_contracts_see(loader):
    # the package loads its build by name (import_fresh): a module outside it (a protocol's
    # drive or axis) is also imported there by a statement, which import-linter reads
    # (pyproject.toml, "protocol-seams")
    graph = grimp.build_graph("hil")
    outside = [name for name in BUILDS[f"{loader}.compiled"]
               if not name.startswith(f"{loader}.")]
    assert outside, "a protocol's modules are in the build"
    for name in outside:
        assert graph.direct_import_exists(importer=loader, imported=name), name
