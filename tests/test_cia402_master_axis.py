"""The master's side of a CiA 402 drive (hil.protocols.cia402.axis) reads what the drive
says as canopen's own tables do."""

from __future__ import annotations

from canopen.profiles.p402 import State402

from hil.protocols.cia402.axis import state_of


def _canopens_state(statusword: int) -> str:
    for name, (mask, value) in State402.SW_MASK.items():
        if statusword & mask == value:
            return name
    return "UNKNOWN"


def test_every_statusword_reads_as_the_state_canopens_mask_table_gives():
    # state_of looks the state up by the statusword's state bits only (a table made once):
    # every one of the 65,536 words must give what the whole word does in canopen's table
    assert [state_of(word) for word in range(1 << 16)] == [
        _canopens_state(word) for word in range(1 << 16)]


def test_the_masters_controlwords_and_statusword_masks_are_canopens():
    """The compiled axis writes canopen's State402 tables out (it must not import canopen with
    hil.hardware): they stay canopen's."""
    from canopen.profiles.p402 import State402

    from hil.protocols.cia402 import axis
    assert (axis.SHUTDOWN, axis.SWITCH_ON, axis.ENABLE, axis.QUICK_STOP, axis.DISABLE_VOLTAGE,
            axis.FAULT_RESET) == (State402.CW_SHUTDOWN, State402.CW_SWITCH_ON,
                                  State402.CW_OPERATION_ENABLED, State402.CW_QUICK_STOP,
                                  State402.CW_DISABLE_VOLTAGE, State402.CW_SWITCH_ON_DISABLED)
    assert axis.SW_MASK == State402.SW_MASK
