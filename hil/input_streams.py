"""Opening a file a user names that is read as a stream, not whole (a CAN log, a rerun
recording: gigabytes, where :func:`hil.input_files.read_input_bytes` reads a config whole):
a regular file of bounded size, or a clear error naming the file, before a byte is read.

What each check stops (as in :mod:`hil.input_files`): a FIFO waits for a writer without
end (python-can's readers opened one and hung), a device (``/dev/zero``) never ends (a text
log's first "line" grew until MemoryError), so the file's kind is checked on a descriptor
opened without blocking; a folder is no file. The descriptor checked is the one read, so
nothing can be put in the file's place between the check and the read.
"""

from __future__ import annotations

import os
import stat
from typing import BinaryIO

from hil.errors import HilError


def open_input_stream(path: os.PathLike | str, what: str, hint: str, limit: int) -> BinaryIO:
    """``path`` (a ``what``: "CAN log", ...) open for reading in binary, blocking; HilError
    naming it where it is missing, a folder, no regular file, over ``limit`` bytes, or cannot
    be opened (``hint``: what to do)."""
    try:
        # O_NONBLOCK: opening a FIFO with no writer returns at once instead of waiting
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except FileNotFoundError:
        raise HilError.single(f"{what} '{path}' does not exist", hint=hint) from None
    except OSError as exc:
        raise HilError.single(f"cannot read {what} '{path}': {exc.strerror}", hint=hint) \
            from None
    try:
        mode = os.fstat(descriptor)
        if stat.S_ISDIR(mode.st_mode):
            raise HilError.single(f"{what} '{path}' is a folder", hint=hint)
        if not stat.S_ISREG(mode.st_mode):
            raise HilError.single(f"{what} '{path}' is not a regular file (a FIFO, a "
                                  "device, a socket)", hint=hint)
        if mode.st_size > limit:
            raise HilError.single(f"{what} '{path}' is {size_in_words(mode.st_size)}, over "
                                  f"the {size_in_words(limit)} hil reads", hint=hint)
        os.set_blocking(descriptor, True)     # a regular file: reads as any file's
        return os.fdopen(descriptor, "rb")
    except BaseException:
        os.close(descriptor)
        raise


def size_in_words(count: int) -> str:
    """A size as people read it: ``512 bytes``, ``3.2 MiB``, ``4 GiB``."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if count >= scale:
            return f"{count / scale:.3g} {unit}"
    return f"{count} bytes"
