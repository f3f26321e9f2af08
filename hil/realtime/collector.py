"""Python's garbage collector around work that shares a process with a real-time loop."""

from __future__ import annotations

import contextlib
import gc
import threading

_collection_pauses = 0
_collection_was_enabled = True
_collection_lock = threading.Lock()


@contextlib.contextmanager
def paused_collection():
    """Python's cyclic garbage collector off while the block runs (process-wide; nested and
    concurrent blocks are counted). For a burst of allocations outside the real-time loop
    (decoding a large goal): a collection the burst triggers runs in one stretch, whichever
    thread it lands in, and held a 500 Hz control loop longer than its period
    (docs/performance.md, "2026-12-06, later: figures from code comments")."""
    global _collection_pauses, _collection_was_enabled
    with _collection_lock:
        _collection_pauses += 1
        if _collection_pauses == 1:
            _collection_was_enabled = gc.isenabled()
            gc.disable()
    try:
        yield
    finally:
        with _collection_lock:
            _collection_pauses -= 1
            if _collection_pauses == 0 and _collection_was_enabled:
                gc.enable()


def release_gradually(items: list, chunk: int = 200) -> None:
    """Empty ``items`` a chunk at a time: freeing a large list of objects in one go is one
    uninterruptible stretch under the GIL (a decoded 10,000-point goal's held the control
    loop for cycles: docs/performance.md, "2026-12-06, later: figures from code comments"); between
    chunks other threads get their turn."""
    while items:
        del items[-chunk:]
