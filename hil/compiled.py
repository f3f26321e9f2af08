"""Modules that the install compiles with mypyc (``setup.py``), and which form of them runs.

:data:`BUILDS` is the one list of them, in builds: the drives' (:data:`COMPILED`, which
``hil.drives`` loads with :func:`import_fresh`), which the controller never imports; the
MIT codec's and the Zenoh transport's (:data:`COMPILED_TRANSPORT`, which ``hil.can``
loads), which both sides run.
``setup.py`` reads them from this file (it imports nothing but the standard library, which
is all a build environment has of hil's needs).

A compiled module sits beside its Python source and Python's import prefers it. After an
edit to the source (an editable install is not rebuilt on edits) the compiled module would
silently run the old code: :func:`import_fresh` then imports the sources instead and warns.
The build writes the SHA-256 of each source it compiled beside it (``<module>.sha256``);
file times would not do (a build that finds its output up to date keeps the old times).
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import sys
import warnings
from pathlib import Path
from types import ModuleType

#: the modules mypyc compiles, in one build (each must type-check with mypy): the drive core's
#: inner loops with its data types, the loop over a plant's cores, and the CiA 402 state
#: machine, which runs for every drive on every plant step and calls the core natively; the
#: profile seam and the MIT family's and Damiao's simulated motors, whose handlers run for
#: every motor on every frame (a G1's lock-step cycle on Damiao motors -8.5 % instructions:
#: docs/performance.md, "2026-12-07: the Damiao motor's handlers compiled"); the simulated
#: CiA 402 drive's cyclic path (its RPDOs, SYNC, TPDOs and the step's follow-up, -14 %
#: instructions a ur3 cycle: "2026-12-07, night: the simulated CiA 402 drive's cyclic path
#: compiled ...")
COMPILED = ("hil.drives.definitions", "hil.drives.references", "hil.drives.core",
            "hil.drives.group", "hil.protocols.cia402.state", "hil.drives.profile",
            "hil.protocols.mit.drive", "hil.protocols.damiao.drive",
            "hil.protocols.cia402.pdo", "hil.protocols.cia402.rpdo", "hil.protocols.cia402.tpdo",
            "hil.protocols.cia402.drive")
#: the MIT family's codec (MIT, Damiao, CubeMars, Robstride's and MyActuator's MIT modes),
#: packed and unpacked once a frame on each side: a command packed in 3.3 µs interpreted,
#: 0.32 µs compiled (docs/performance.md, "2026-12-06, issue 69: the MIT family's codec
#: compiled, a Damiao motor's registers read once")
COMPILED_MIT_CODEC = ("hil.protocols.mit.codec",)
#: the Zenoh CAN transport's wire codec and link account, run on both sides for every
#: message, a section a bus: a G1's message each way (6 sections of 5 frames) put and taken
#: in 87 µs from the sources, 60 µs compiled (tools/transport_cost.py; docs/performance.md,
#: "2026-12-07: the transport's codec compiled, a drive's calls a cycle cut"); and the
#: router's dispatch, every frame to its handlers on both sides, on every bus ("2026-12-08:
#: the router's dispatch and the fault watch compiled, a watchdog's heartbeats in one message")
COMPILED_TRANSPORT = ("hil.can.link_statistics", "hil.can.zenoh_wire", "hil.can.link_account",
                      "hil.can.routes")
#: the master's side of an axis, the MIT family's and Damiao's axes, whose handlers run for
#: every axis on every cycle, the cycle's exchange that calls them and the watch over their
#: faults and silences (docs/performance.md, "2026-12-07: the Damiao motor's handlers
#: compiled"; "2026-12-08: the router's dispatch and the fault watch compiled ...")
COMPILED_AXES = ("hil.hardware.axis", "hil.protocols.mit.axis", "hil.protocols.damiao.axis",
                 "hil.protocols.cia402.axis", "hil.hardware.exchange", "hil.hardware.watch")
#: each build's shared library (inside the package) and its modules
BUILDS = {"hil.drives.compiled": COMPILED, "hil.protocols.mit.compiled": COMPILED_MIT_CODEC,
          "hil.can.compiled": COMPILED_TRANSPORT, "hil.hardware.compiled": COMPILED_AXES}


def import_fresh(*names: str) -> None:
    """Import modules compiled together, in order: all compiled where the build's record of
    every source still matches it, else all from their sources, with a warning (compiled
    modules of one build call each other's classes directly, so they cannot be mixed)."""
    specs = []
    for name in names:
        if name in sys.modules:
            continue
        spec = importlib.util.find_spec(name)
        if spec is None or spec.origin is None:
            raise ModuleNotFoundError(f"no module named '{name}'", name=name)
        specs.append(spec)
    files = [_source_and_compiled(spec) for spec in specs]
    edited = [source for source, compiled in files
              if compiled is not None and not _compiled_from(source)]
    if edited:
        warnings.warn(f"{', '.join(map(str, edited))} changed since compiled: "
                      f"{', '.join(names)} run interpreted (slower) until `pip install -e .` "
                      f"compiles them again", stacklevel=2)
        specs = [importlib.util.spec_from_file_location(spec.name, source)
                 for spec, (source, _) in zip(specs, files)]
    for spec in specs:
        _load(spec)


def is_compiled(module: ModuleType) -> bool:
    """Whether ``module`` runs as a compiled extension (not from Python source)."""
    return isinstance(module.__spec__.loader, importlib.machinery.ExtensionFileLoader)


def _source_and_compiled(spec) -> tuple[Path, Path | None]:
    """The module's Python source, and its compiled form where that is what would load."""
    origin = Path(spec.origin)
    source = origin.with_name(spec.name.rpartition(".")[2] + ".py")
    if isinstance(spec.loader, importlib.machinery.ExtensionFileLoader) and source.exists():
        return source, origin
    return origin, None


def _compiled_from(source: Path) -> bool:
    """Whether the build recorded ``source``, as it is now, as what it compiled."""
    record = source.with_suffix(".sha256")
    return record.exists() and record.read_text().strip() == \
        hashlib.sha256(source.read_bytes()).hexdigest()


def _load(spec) -> None:
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[spec.name]
        raise
    parent, _, child = spec.name.rpartition(".")
    if parent:
        setattr(sys.modules[parent], child, module)
