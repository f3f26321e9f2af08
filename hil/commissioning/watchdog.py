"""What watchdog the drives of a bench ``hil init`` wrote run with, and why.

``hil init`` writes no ``watchdog_timeout``: each drive keeps its protocol's default (the
product's own, :meth:`ProtocolOptions.drive_defaults`, where its maker documents one; hil's
bus config default where the protocol gives none), as a drive out of its box would. This
says, per protocol and its buses, what that is.
"""

from __future__ import annotations

from hil.bus_config import SystemConfig


def watchdog_choices(config: SystemConfig) -> list[str]:
    """One line per protocol of ``config``'s drives (and per watchdog, where its drives
    differ): the watchdog, the buses, and whose default it is."""
    found: dict[tuple[str, float, bool], list[str]] = {}
    for bus in config.buses:
        for drive in bus.drives:
            product = drive.options.drive_defaults() if drive.options is not None else {}
            key = (drive.protocol, drive.watchdog_timeout, "watchdog_timeout" in product)
            if bus.name not in found.setdefault(key, []):
                found[key].append(bus.name)
    lines = []
    for (name, timeout, own), buses in found.items():
        value = f"{timeout:g} s" if timeout > 0 else "off"
        why = ("the protocol's own default (its drives' documented setting)" if own else
               "hil's default (the protocol documents none)")
        lines.append(f"watchdog {value} for the {name} drives on {', '.join(buses)}: {why}; "
                     "set watchdog_timeout in the config to change it")
    return lines
