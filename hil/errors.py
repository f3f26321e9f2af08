"""User-facing errors and warnings.

Every problem a user can cause (a malformed robot description, a bad bus
config, ...) is reported as a :class:`Diagnostic` that names where it is
(file and line when known), what is wrong and what to do. The CLI prints them
instead of a traceback.
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


class HilError(Exception):
    """An error caused by user input; carries one or more diagnostics.

    ``str(exc)`` is the full, printable report. The CLI catches this type and
    exits non-zero without a traceback.
    """

    #: the CLI's exit status for it
    exit_status = 1

    def __init__(self, diagnostics: Diagnostic | list[Diagnostic] | tuple[Diagnostic, ...]):
        if isinstance(diagnostics, Diagnostic):
            diagnostics = [diagnostics]
        self.diagnostics: tuple[Diagnostic, ...] = tuple(diagnostics)
        super().__init__("\n".join(str(d) for d in self.diagnostics))

    @classmethod
    def single(cls, message: str, file: Path | None = None, line: int | None = None,
               hint: str | None = None) -> "HilError":
        return cls(error(message, file, line, hint))


def did_you_mean(word: str, choices) -> str:
    """`` (did you mean 'x'?)`` where a choice is close to a misspelt ``word`` (difflib's
    ratio, its default cutoff 0.6, as Python's own NameError suggestions), else ''."""
    import difflib                                  # noqa: PLC0415 (only on an error)

    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""
