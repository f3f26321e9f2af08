"""hil: a hardware-in-the-loop controller stack for robot arms.

The package mirrors the data flow, lowest stage first:
description -> transmissions -> plant -> (drives -> CAN -> hardware interface
-> controllers -> messaging -> visualisation) -> cli. A stage imports only the
stages below it: pyproject.toml's import-linter contracts say which, and the
tests check them (docs/design.md, "Layout").

Two wings meet over CAN (docs/design.md, "The two wings"): what ``hil sim`` runs (the
drives' wing: simulator, drives, plant, each protocol's ``drive``) and what ``hil
control`` runs (the controller's wing: control_node, controllers, hardware, messaging,
each protocol's ``axis``). Neither imports the other; can, protocols' codecs, bus_config,
transmissions and description lie below both.
"""

__version__ = "0.1.0"
