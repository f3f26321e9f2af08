"""Commissioning a bench for any robot description: what ``hil init`` writes.

:mod:`~hil.commissioning.sizing` picks a motor class and reduction for a joint from its
limits and gravity load; :mod:`~hil.commissioning.initial` writes the first bus config (a
drive per actuated joint, the transmissions it sized, the buses the load check allows).
"""
