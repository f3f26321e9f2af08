"""Names a package offers but imports only when first used (PEP 562).

A package's ``__init__`` keeps its light names (typed data) eager and its heavy ones (a
parser, a reader of files) behind :func:`lazy_exports`, so importing the data types does not
load the machinery that makes them: the controller's hardware interface takes a parsed
config without loading the YAML parser or the description reader.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable


def lazy_exports(package: str, names: dict[str, str]) -> Callable[[str], object]:
    """A module ``__getattr__`` for ``package``: each name of ``names`` is imported from the
    module it maps to on first use."""

    def attribute(name: str) -> object:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(names[name]), name)
    return attribute
