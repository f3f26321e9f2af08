"""What ``hil check`` asks of a CiA 402 drive's files before ``hil sim`` starts it: the
object dictionary the drive would start with (its personality's for its node id, a vendor
file's PDO parameters as they stand) and the parameter file it would restore, each value
checked as the restore checks it (:meth:`.storage.ParameterStore.restore`, into a
:class:`.written.StoredDictionary`: the checks without the drive, which the controller side
of the bus config's reading does not load). So a file ``hil check`` passes starts; what it
refuses is named with the file and the value."""

from __future__ import annotations

from hil.errors import HilError
from hil.protocols.cia402.eds import checked_dictionary
from hil.protocols.cia402.eds_file import read_text
from hil.protocols.cia402.pdo_parameters import configuration_problems
from hil.protocols.cia402.storage import ParameterStore
from hil.protocols.cia402.written import StoredDictionary
from hil.resources import eds_path

#: the problems named in one message (the rest counted)
SHOWN = 5


def start_problem(node_id: int, options) -> str | None:
    """Why the drive of ``node_id`` with these options would not start as its files say,
    or None."""
    eds = (options.eds if options is not None else None) or eds_path()
    kept = options.parameter_file if options is not None else None
    try:      # the personality's dictionary (:mod:`.personality`, which the drive side has)
        node = StoredDictionary(checked_dictionary(eds, read_text(eds), node_id), node_id)
        store = ParameterStore(kept)
    except ValueError as exc:
        return str(exc)
    except HilError as exc:        # the parameter file's reading
        said = exc.diagnostics[0]
        where = f"{said.file}" + (f" line {said.line}" if said.line else "") + ": "
        return f"parameter_file: {where if said.file else ''}{said.message}"
    found = configuration_problems(node)
    if found:
        return (f"eds: {eds} gives PDO parameters the drive does not take "
                f"(CiA 301 7.5.2.35-38): {_listed(found)}")
    found = store.restore(node, communication_only=False)
    if found:
        return (f"parameter_file: {kept} holds values the drive does not take: "
                f"{_listed(found)} (remove them, or the file, and save the parameters again)")
    return None


def _listed(found: list[str]) -> str:
    more = len(found) - SHOWN
    return "; ".join(found[:SHOWN]) + (f"; and {more} more" if more > 0 else "")
