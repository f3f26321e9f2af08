"""Fails unless every module of hil.compiled's builds runs compiled in this environment.

setup.py's extensions are optional: a build mypyc refused (a type error) falls back to the
sources without a word, and the measured speed with it. tools/wheel_check.sh runs this in the
wheel's environment, .ci/run in the checkout's once it holds the wheel's compiled modules.
"""

import importlib
import sys

from hil.compiled import BUILDS, is_compiled

for package in ("hil.can", "hil.drives", "hil.hardware", "hil.protocols.mit"):
    importlib.import_module(package)          # each loads its builds
modules = [name for names in BUILDS.values() for name in names]
missing = [name for name in modules if not is_compiled(importlib.import_module(name))]
if missing:
    sys.exit(f"{sys.argv[0]}: not compiled here: {', '.join(missing)} (its build failed: "
             "`pip wheel -v .` shows mypyc's error)")
print(f"the {len(modules)} modules of {len(BUILDS)} builds run compiled")
