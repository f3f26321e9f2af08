"""User-facing errors and warnings.

Every problem hil reports is a :class:`Diagnostic` that names where it is (file and line,
or bus and node), what is wrong and what to do; the CLI prints them instead of a traceback.
The exceptions that carry them are one family under :class:`HilError`, each a stable type a
user's test can catch, as python-can's ``CanError`` -> ``CanInitializationError`` /
``CanOperationError`` / ``CanTimeoutError`` and canopen's ``SdoError`` ->
``SdoAbortedError``:

- :class:`ConfigError`: what the user wrote or gave says something hil refuses, a file
  (``.path``, ``.line``: a bus config, a robot description, a controllers file, a
  trajectory, a CAN log) or, as :class:`UsageError`, a command-line value; the diagnostic's
  hint says what to write instead.
- :class:`RuntimeFault`: something that happened on a running bench (``.bus``, ``.node``,
  ``.device``): :class:`BusError` (a bus cannot be opened or used), :class:`DriveError` (a
  drive answered wrongly or faulted), :class:`ProcessError` (a hil process or service not
  there, already there, or not starting), :class:`BringUpError` (the drives were not
  brought up) with :class:`BootTimeout` (drives not heard after their reset) and
  :class:`EnableError` (drives that did not enable).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from pathlib import Path


class Severity(enum.Enum):
    ERROR = "error"
    WARNING = "warning"


@dataclass(frozen=True)
class Diagnostic:
    """One problem found in user input."""

    severity: Severity
    message: str
    file: Path | None = None
    line: int | None = None
    hint: str | None = None

    @property
    def location(self) -> str:
        if self.file is None:
            return ""
        return f"{self.file}:{self.line}" if self.line else str(self.file)

    def __str__(self) -> str:
        where = f"{self.location}: " if self.file is not None else ""
        text = f"{where}{self.severity.value}: {self.message}"
        if self.hint:
            text += f"\n    what to do: {self.hint}"
        return text


def error(message: str, file: Path | None = None, line: int | None = None,
          hint: str | None = None) -> Diagnostic:
    return Diagnostic(Severity.ERROR, message, file, line, hint)


def warning(message: str, file: Path | None = None, line: int | None = None,
            hint: str | None = None) -> Diagnostic:
    return Diagnostic(Severity.WARNING, message, file, line, hint)


#: what an error carries: one diagnostic or several
Diagnostics = Diagnostic | list[Diagnostic] | tuple[Diagnostic, ...]


class HilError(Exception):
    """An error hil reports to its user; carries one or more diagnostics.

    ``str(exc)`` is the full, printable report. The CLI catches this type and exits with
    :attr:`exit_status`, without a traceback. Raise one of its kinds below: a
    :class:`ConfigError` or a :class:`RuntimeFault`.
    """

    #: the CLI's exit status for it
    exit_status = 1

    def __init__(self, diagnostics: Diagnostics):
        if isinstance(diagnostics, Diagnostic):
            diagnostics = [diagnostics]
        self.diagnostics: tuple[Diagnostic, ...] = tuple(diagnostics)
        super().__init__("\n".join(str(d) for d in self.diagnostics))

    @classmethod
    def single(cls, message: str, file: Path | None = None, line: int | None = None,
               hint: str | None = None, **fields) -> "HilError":
        """One error diagnostic as this kind (``fields``: its own, e.g. ``bus=``)."""
        return cls(error(message, file, line, hint), **fields)


class ConfigError(HilError):
    """What the user wrote or gave hil says something it refuses: a file (a bus config, a
    robot description, a controllers file, a trajectory, a CAN log), each diagnostic naming
    the file and line and, in its hint, what to write."""

    @property
    def path(self) -> Path | None:
        """The file of the first error that names one (None: a value given otherwise, on the
        command line)."""
        located = self._located()
        return None if located is None else located.file

    @property
    def line(self) -> int | None:
        """The line in :attr:`path` (1-based; None where the file's reader cannot tell)."""
        located = self._located()
        return None if located is None else located.line

    def _located(self) -> Diagnostic | None:
        # the errors first: the warnings that travel along may name other files
        ranked = sorted(self.diagnostics, key=lambda d: d.severity is not Severity.ERROR)
        return next((d for d in ranked if d.file is not None), None)


class UsageError(ConfigError):
    """A command-line value hil refuses (an option's value, a robot's name, a path to write
    to); its hint says what to give instead."""


class RuntimeFault(HilError):
    """Something that happened on a running bench, not in a file: on which bus (its name in
    the bus config), at which node id, to which device (the joint or drive as hil labels
    it), where one is concerned; ``None`` where not."""

    def __init__(self, diagnostics: Diagnostics,
                 *, bus: str | None = None, node: int | None = None,
                 device: str | None = None):
        super().__init__(diagnostics)
        self.bus = bus
        self.node = node
        self.device = device


class BusError(RuntimeFault):
    """A bus that cannot be opened or used (python-can's ``CanInitializationError`` and
    ``CanOperationError``, hil's Zenoh buses' links)."""


class DriveError(RuntimeFault):
    """A drive that answered wrongly, refused a request or faulted (an SDO abort, an
    emergency, a reply that never came); ``.bus`` and ``.node`` say which."""


class ProcessError(RuntimeFault):
    """A hil process or service that is not there (no controller, no simulator, no ROS 2
    server on the network), is there already (a second ``hil sim`` of one robot), or cannot
    start (a Zenoh router's port taken)."""


class BringUpError(RuntimeFault):
    """The drives were not brought up (booted, configured, enabled); ``.drives`` labels
    every drive concerned (``.device`` the first)."""

    def __init__(self, diagnostics: Diagnostics,
                 *, drives: tuple[str, ...] = (), bus: str | None = None,
                 node: int | None = None):
        super().__init__(diagnostics, bus=bus, node=node,
                         device=drives[0] if drives else None)
        self.drives = tuple(drives)


class BootTimeout(BringUpError, TimeoutError):
    """Drives not heard within the boot timeout after their reset (a ``TimeoutError`` as
    well, as python-can's ``CanTimeoutError``); ``.timeout`` is that timeout (s)."""

    def __init__(self, diagnostics: Diagnostics,
                 *, timeout: float, drives: tuple[str, ...] = (), bus: str | None = None,
                 node: int | None = None):
        super().__init__(diagnostics, drives=drives, bus=bus, node=node)
        self.timeout = timeout


class EnableError(BringUpError):
    """Drives that booted but did not enable (a fault, a silence, the enable timeout)."""


def did_you_mean(word: str, choices) -> str:
    """`` (did you mean 'x'?)`` where a choice is close to a misspelt ``word`` (difflib's
    ratio, its default cutoff 0.6, as Python's own NameError suggestions), else ''."""
    import difflib                                  # noqa: PLC0415 (only on an error)

    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""
