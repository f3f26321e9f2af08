"""hil: a hardware-in-the-loop controller stack for robot arms.

The package mirrors the data flow, lowest stage first:
description -> transmissions -> plant -> (drives -> CAN -> hardware interface
-> controllers -> messaging -> visualisation) -> cli. A stage imports only the
stages below it: pyproject.toml's import-linter contracts say which, and the
tests check them (docs/design.md, "Layout").
"""

__version__ = "0.1.0"
