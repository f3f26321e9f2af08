"""Reading a file a user names (a bus config, a robot description, a trajectory): a regular
file of bounded size, or a clear error. A FIFO or a device (``/dev/zero``) would block or
fill the memory; a file of gigabytes is no description."""

from __future__ import annotations

from pathlib import Path

from hil.errors import HilError

#: the largest input file hil reads (bytes)
MAX_FILE_BYTES = 16 * 1024 * 1024


def read_input_file(path: Path, what: str, hint: str) -> str:
    """The text of ``path`` (a ``what``: "bus config", ...), UTF-8 with undecodable bytes
    replaced; HilError naming the file where it is no regular file of at most
    MAX_FILE_BYTES, or cannot be read."""
    path = Path(path)
    try:
        if not path.exists():
            raise HilError.single(f"{what} '{path}' does not exist", hint=hint)
        if not path.is_file():
            raise HilError.single(f"{what} '{path}' is not a regular file", hint=hint)
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise HilError.single(f"{what} '{path}' is {size} bytes, over the {MAX_FILE_BYTES} "
                                  "hil reads", hint=hint)
        return path.read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise HilError.single(f"cannot read {what} '{path}': {exc.strerror}", hint=hint) from None
