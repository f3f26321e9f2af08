"""Build hook: the drive core compiled by mypyc where the machine has a C compiler.

The drive core's inner loops and the CiA 402 state machine run for every drive on every plant
step and cycle, the MIT family's frame packing and the Zenoh transport's codec on both
sides for every frame (``hil.compiled.BUILDS`` lists the modules). Compiled, the same typed
Python takes about 30 % off a lock-step cycle (docs/performance.md). The Python files stay
the only source: without a compiler the install goes on and they run interpreted
(``hil.compiled`` tells which form runs).
"""

import hashlib
import os
import runpy
import shutil
from pathlib import Path

from mypyc.build import mypycify
from setuptools import setup
from setuptools.command.build_ext import build_ext
from setuptools.command.build_py import build_py

#: the modules mypyc compiles, by build: hil.compiled's lists, read from its file (importing
#: hil would need its dependencies, which a build environment has not)
BUILDS = runpy.run_path("hil/compiled.py")["BUILDS"]
MODULES = [module for modules in BUILDS.values() for module in modules]


class BuildExt(build_ext):
    """Also writes, beside each compiled module, the SHA-256 of the source it was compiled
    from (``<module>.sha256``): ``hil.compiled`` runs the sources where one differs."""

    def finalize_options(self):
        super().finalize_options()
        if self.parallel is None:       # the builds' C compiled side by side, a CPU each
            self.parallel = True

    def run(self):
        super().run()
        for module in MODULES:
            source = _source(module)
            compiled = Path(self.get_ext_fullpath(module))
            if compiled.exists():
                digest = hashlib.sha256(source.read_bytes()).hexdigest()
                compiled.with_name(source.stem + ".sha256").write_text(digest + "\n")


class BuildPy(build_py):
    """Also copies the repository's data folders into the package of a built wheel
    (``hil/data/robots``, ``hil/data/bus_config``): hil.resources finds them there after a
    ``pip install``, and in the checkout itself for an editable install."""

    DATA = ("robots", "bus_config")

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for name in self.DATA:
            shutil.copytree(name, Path(self.build_lib) / "hil" / "data" / name,
                            dirs_exist_ok=True, ignore=shutil.ignore_patterns("__pycache__"))


def _source(module: str) -> Path:
    return Path(*module.split(".")).with_suffix(".py")


def optional_extensions():
    # their imports are checked by the tests, not here: the build environment has only mypy,
    # so a third-party module they import (python-can) is Any to mypyc; one shared library
    # for the group, inside the package (by default it is a top-level module named by a hash
    # of the modules' names)
    extensions = [extension for group, modules in BUILDS.items()
                  for extension in mypycify(["--follow-imports=skip", "--ignore-missing-imports",
                                             *(str(_source(module)) for module in modules)],
                                            opt_level="3", group_name=group)]
    for extension in extensions:
        extension.optional = True        # a failed compile leaves the modules interpreted
    return extensions


# HIL_COMPILE=0: no build at all, the modules interpreted (.ci/run installs hil editable so
# while it builds the wheel beside it, then takes the wheel's compiled modules: one build)
setup(ext_modules=[] if os.environ.get("HIL_COMPILE") == "0" else optional_extensions(),
      cmdclass={"build_ext": BuildExt, "build_py": BuildPy})
