"""Which controllers a switch request deactivates and activates, or why it switches
nothing, as ros2_control's controller_manager decides it (jazzy branch,
controller_manager/src/controller_manager.cpp: switch_controller_cb,
check_for_interfaces_availability_to_activate, evaluate_switch_result; pinned by its tests
test_load_controller.cpp and test_controller_manager_srvs.cpp), and the messages it answers.

hil's controllers are all loaded and configured (inactive or active), so the checks for
unconfigured controllers, chained controllers and fallback controllers have nothing to find.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from dataclasses import dataclass


class Strictness(enum.IntEnum):
    """controller_manager_msgs/SwitchController's strictness."""

    BEST_EFFORT = 1
    STRICT = 2


@dataclass(frozen=True)
class SwitchResult:
    ok: bool
    message: str = ""


@dataclass(frozen=True)
class SwitchPlan:
    """A switch that goes ahead: deactivate, then activate, then answer ``message``."""

    deactivate: tuple[str, ...]
    activate: tuple[str, ...]
    message: str


NOTHING_TO_DO = ("After checking the controllers, no controllers need to be activated or "
                 "deactivated.")


def plan_switch(activate: Sequence[str], deactivate: Sequence[str], strictness: Strictness,
                claims: Mapping[str, tuple[str, ...]], active: Sequence[str],
                joints: Sequence[str]) -> SwitchPlan | SwitchResult:
    """The switch of a request over the controllers ``claims`` names (each with its command
    interfaces, ``joint/interface``), of which ``active`` are active, on the hardware's
    ``joints``; or the refusal (ok False) or the OK with nothing to switch."""
    strict = strictness is Strictness.STRICT
    # the deactivations are listed first, as switch_controller_cb lists them
    deactivating, message, found = _existing(deactivate, "deactivate", claims, strict)
    if not found:
        return SwitchResult(False, message)
    activating, more, found = _existing(activate, "activate", claims, strict)
    if not found:
        return SwitchResult(False, message + more)
    for name in list(activating):
        if name in active and name not in deactivating:
            if strict:
                return SwitchResult(False, f"Controller with name '{name}' is already active.")
            activating.remove(name)
    for name in list(deactivating):
        if name not in active:
            if strict:
                return SwitchResult(False, f"Controller with name '{name}' can not be "
                                           "deactivated since it is not active.")
            deactivating.remove(name)
    if not activating and not deactivating:
        return SwitchResult(True, NOTHING_TO_DO)
    refused = _unavailable(activating, deactivating, claims, active) or \
        (_uncovered(activating, deactivating, claims, active, joints) if strict else "")
    if refused:
        return SwitchResult(False, refused)
    return SwitchPlan(tuple(deactivating), tuple(activating),
                      _success(deactivating, activating, strict))


def _existing(names: Sequence[str], action: str, claims: Mapping[str, tuple[str, ...]],
              strict: bool) -> tuple[list[str], str, bool]:
    """The controllers of ``names`` that exist, what was said of the others, and whether the
    list may go on: STRICT stops at the first unknown one; otherwise an unknown one is "not
    a critical error" only where the list names one that exists (switch_controller_cb's
    list_controllers: ERROR while its request list is empty)."""
    found, message = [], ""
    for name in names:
        if name in claims:
            found.append(name)
            continue
        problem = (f"Could not {action} controller with name '{name}' because no controller "
                   "with this name exists")
        if strict:
            return [], problem, False
        message += problem + "\n"
    return found, message, bool(found) or not names


def _unavailable(activating: list[str], deactivating: list[str],
                 claims: Mapping[str, tuple[str, ...]], active: Sequence[str]) -> str:
    """check_for_interfaces_availability_to_activate: an interface a controller that stays
    active claims, or one another controller of this switch takes, is not available (in
    either strictness). Where a controller is restarted (in both lists), controller_manager
    leaves it out of this check and its activation fails after the deactivations; hil checks
    it with the others, so that a refused switch switches nothing (hil's choice)."""
    kept = {claim for name in active if name not in deactivating for claim in claims[name]}
    taken: set[str] = set()
    for name in activating:
        for claim in claims[name]:
            if claim in kept:
                return (f"Unable to activate controller '{name}' since the command interface "
                        f"'{claim}' is currently claimed by another controller.")
            if claim in taken:
                return (f"Unable to activate controller '{name}' since the command interface "
                        f"'{claim}' will be used by another controller that is being "
                        "activated.")
            taken.add(claim)
    return ""


def _uncovered(activating: list[str], deactivating: list[str],
               claims: Mapping[str, tuple[str, ...]], active: Sequence[str],
               joints: Sequence[str]) -> str:
    """hil's own rule (controller_manager has none): a STRICT switch may not leave a joint
    without any controller; with BEST_EFFORT that joint holds its last command."""
    after = [n for n in active if n not in deactivating] + activating
    claimed = {claim for name in after for claim in claims[name]}
    uncovered = [j for j in joints
                 if f"{j}/position" not in claimed and f"{j}/velocity" not in claimed]
    if not uncovered:
        return ""
    return (f"the switch would leave joint(s) {', '.join(uncovered)} without a controller "
            "(STRICT; with BEST_EFFORT they hold their last command)")


def _success(deactivating: list[str], activating: list[str], strict: bool) -> str:
    """evaluate_switch_result's message; a switch that is not STRICT lists what it did."""
    message = "Successfully switched controllers!"
    if not strict and deactivating:
        message += f"\nDeactivated controllers: [ {' '.join(deactivating)} ]"
    if not strict and activating:
        message += f"\nActivated controllers: [ {' '.join(activating)} ]"
    return message
