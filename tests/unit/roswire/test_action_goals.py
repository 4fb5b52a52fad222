"""Action goal rules without I/O: cancel decisions (rcl_action's), status labels, goal ids."""

from __future__ import annotations

import uuid

import pytest

from fleetlink.roswire.action_goals import (
    ZERO_ID,
    CancelCode,
    GoalStatus,
    action_part,
    decide_cancel,
    goal_id_bytes,
    goal_id_text,
    status_label,
)

pytestmark = pytest.mark.unit

A, B, C = (bytes([n]) * 16 for n in (1, 2, 3))


@pytest.mark.parametrize(
    ("goals", "goal_id", "stamp", "code", "canceling"),
    [
        ({A: GoalStatus.EXECUTING}, A, 0, CancelCode.ERROR_NONE, (A,)),
        ({A: GoalStatus.ACCEPTED}, A, 0, CancelCode.ERROR_NONE, (A,)),
        ({A: GoalStatus.SUCCEEDED}, A, 0, CancelCode.ERROR_GOAL_TERMINATED, ()),
        ({A: GoalStatus.ABORTED}, A, 0, CancelCode.ERROR_GOAL_TERMINATED, ()),
        ({A: GoalStatus.CANCELING}, A, 0, CancelCode.ERROR_REJECTED, ()),
        ({A: GoalStatus.EXECUTING}, B, 0, CancelCode.ERROR_UNKNOWN_GOAL_ID, ()),
        ({}, B, 0, CancelCode.ERROR_UNKNOWN_GOAL_ID, ()),
        (
            {A: GoalStatus.EXECUTING, B: GoalStatus.SUCCEEDED, C: GoalStatus.ACCEPTED},
            ZERO_ID,
            0,
            CancelCode.ERROR_NONE,
            (A, C),
        ),
        ({A: GoalStatus.SUCCEEDED}, ZERO_ID, 0, CancelCode.ERROR_REJECTED, ()),
    ],
)
def test_cancel_follows_rcl_action(
    goals: dict[bytes, GoalStatus], goal_id: bytes, stamp: int, code: CancelCode, canceling: tuple[bytes, ...]
) -> None:
    decision = decide_cancel(goals, goal_id, stamp, {})
    assert decision.code is code
    assert decision.canceling == canceling


def test_cancel_by_stamp_takes_goals_accepted_until_then() -> None:
    goals = {A: GoalStatus.EXECUTING, B: GoalStatus.EXECUTING, C: GoalStatus.EXECUTING}
    accepted = {A: 100, B: 200, C: 300}
    assert decide_cancel(goals, ZERO_ID, 200, accepted).canceling == (A, B)
    assert decide_cancel(goals, C, 150, accepted).canceling == (C, A)


def test_status_labels_and_terminal_states() -> None:
    assert status_label(4) == "succeeded"
    assert status_label(42) == "status 42"
    assert [s.label for s in GoalStatus if s.terminal] == ["succeeded", "canceled", "aborted"]
    assert CancelCode.ERROR_GOAL_TERMINATED.meaning == "the goal had already finished"


def test_goal_ids_round_trip_and_refuse_garbage() -> None:
    raw = uuid.uuid4().bytes
    text = goal_id_text(raw)
    assert goal_id_bytes(text) == raw
    assert goal_id_bytes(text.replace("-", "").upper()) == raw
    with pytest.raises(ValueError, match="16 bytes"):
        goal_id_text(b"short")
    with pytest.raises(ValueError, match="hexadecimal"):
        goal_id_bytes("not-a-uuid")


def test_action_parts() -> None:
    assert action_part("/tb4_01/dock", "send_goal") == "/tb4_01/dock/_action/send_goal"
