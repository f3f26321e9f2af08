"""A bus' subscribers, by identifier and by mask, and a delivery's frames handed to them: the
part of :class:`hil.can.router.FrameRouter` that runs for every frame on both sides.

Compiled with the transport (:data:`hil.compiled.COMPILED_TRANSPORT`): the router itself is a
python-can ``Listener``, a class a compiled (native) class cannot derive from, so the loop
over frames and handlers lives here and the router hands it each delivery in one call.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from hil.can.frame import Frame

#: what a subscriber is called with: each frame of its identifier
Handler = Callable[[Frame], None]
#: a table of handlers by an identifier's masked bits: (mask, extended, remote, table)
MaskedTable = tuple[int, bool, bool, dict[int, list[Handler]]]


class Routes:
    """Handlers by identifier (and mask), and the dispatch of frames to them.

    ``refuse`` is called with a frame, the handler and what it raised, for a handler that
    raised on a frame (the others still get it); ``fd_on_classical``, where not None, with
    each CAN FD frame, which then reaches no handler (a classical bus' controller destroys
    it). Error frames reach no handler."""

    def __init__(self, refuse: Callable[[Frame, Handler, Exception], None],
                 fd_on_classical: Callable[[Frame], None] | None):
        self._refuse = refuse
        self._fd_on_classical = fd_on_classical
        # data frames by identifier, standard and extended apart (an extended id below 0x800
        # is another frame than the standard one of that number); remote frames apart
        self._by_id: list[dict[int, list[Handler]]] = [{}, {}, {}, {}]
        #: frames by their identifier's masked bits, a table per (mask, extended, remote):
        #: a frame is looked up once a mask, not held against every subscriber (a bus of N
        #: drives subscribed by mask made each frame's dispatch N checks, a cycle's N²)
        self._masked: list[MaskedTable] = []

    def subscribe(self, identifier: int, handler: Handler, extended: bool, remote: bool,
                  mask: int | None) -> None:
        """Add ``handler`` for ``identifier`` (with ``mask``: for every identifier whose
        masked bits equal its)."""
        if mask is not None:
            self._masked = self._masked_with(identifier, mask, extended, remote, handler, True)
            return
        routes = self._by_id[extended + 2 * remote]
        # a new list: a delivery in progress reads the one it has
        routes[identifier] = [*routes.get(identifier, []), handler]

    def unsubscribe(self, identifier: int, handler: Handler, extended: bool, remote: bool,
                    mask: int | None) -> None:
        """Remove one :meth:`subscribe` of these arguments (none: nothing happens)."""
        if mask is not None:
            self._masked = self._masked_with(identifier, mask, extended, remote, handler, False)
            return
        routes = self._by_id[extended + 2 * remote]
        left = [each for each in routes.get(identifier, []) if each != handler]
        if left:
            routes[identifier] = left
        else:
            routes.pop(identifier, None)

    def _masked_with(self, identifier: int, mask: int, extended: bool, remote: bool,
                     handler: Handler, add: bool) -> list[MaskedTable]:
        """The masked tables with ``handler`` added to (or removed from) those of
        ``identifier & mask``, as new lists and tables (a delivery in progress reads the
        ones it has)."""
        key = identifier & mask
        tables: list[MaskedTable] = []
        found = False
        for each_mask, each_extended, each_remote, table in self._masked:
            if each_mask == mask and each_extended == extended and each_remote == remote:
                found = True
                table = {**table, key: _changed(table.get(key, []), handler, add)}
                table = {k: handlers for k, handlers in table.items() if handlers}
            if table:
                tables.append((each_mask, each_extended, each_remote, table))
        if not found and add:
            tables.append((mask, extended, remote, {key: [handler]}))
        return tables

    def by_identifier(self, identifier: int, extended: bool, remote: bool
                      ) -> tuple[Handler, ...]:
        """The handlers of ``identifier`` by identifier (not by mask)."""
        return tuple(self._by_id[extended + 2 * remote].get(identifier, []))

    def any(self) -> bool:
        """Whether any handler is subscribed, by identifier or by mask."""
        return any(self._by_id) or bool(self._masked)

    def dispatch(self, frames: Iterable[Frame]) -> None:
        """Each frame to its handlers, in order."""
        by_id, masked, fd_on_classical = self._by_id, self._masked, self._fd_on_classical
        for frame in frames:
            if frame.error:
                continue
            if frame.fd and fd_on_classical is not None:
                fd_on_classical(frame)
                continue
            handlers = by_id[frame.extended + 2 * frame.remote].get(frame.identifier)
            if masked:
                handlers = _with_masked(frame, masked, handlers)
            if handlers is not None:
                for handler in handlers:
                    try:
                        handler(frame)
                    except Exception as exc:
                        self._refuse(frame, handler, exc)

    def clear(self) -> None:
        """No handler from now on, not even for the rest of a delivery in progress (the
        tables are emptied in place, where that delivery reads them)."""
        for routes in self._by_id:
            routes.clear()
        for _mask, _extended, _remote, table in self._masked:
            table.clear()
        self._masked.clear()


def _changed(handlers: list[Handler], handler: Handler, add: bool) -> list[Handler]:
    return [*handlers, handler] if add else [each for each in handlers if each != handler]


def _with_masked(frame: Frame, masked: list[MaskedTable], handlers: list[Handler] | None
                 ) -> list[Handler] | None:
    """``handlers`` (the frame's by identifier, or None), then those of the masked tables that
    the frame's masked bits select."""
    for mask, extended, remote, table in masked:
        if frame.extended == extended and frame.remote == remote:
            more = table.get(frame.identifier & mask)
            if more is not None:
                handlers = more if handlers is None else [*handlers, *more]
    return handlers
