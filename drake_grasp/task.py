"""The grasping task's named constants and its success rule, shared by trials and the closed loop.

One attempt (paper Sec. IV-D): the open hand approaches from `PREGRASP_DISTANCE`
back along the approach axis, closes for `CLOSE_DURATION`, lifts `LIFT_TRAVEL`
in `LIFT_DURATION` and holds for `HOLD_DURATION`. It succeeds when the object
ends at least `LIFT_HEIGHT` higher. The self-supervised trials that label the
stability CNN and the closed loop judge with the same `judge_lift`, so a label
means the same thing in both.
"""

from __future__ import annotations

import enum

PREGRASP_DISTANCE = 0.10  # hand retreat along -z of G before the approach [m]
LIFT_HEIGHT = 0.15  # success requires the object this much higher [m]
LIFT_TRAVEL = 0.20  # the hand rises this much, so that a held object, even pivoting, clears LIFT_HEIGHT [m]
SETTLE_AFTER_APPROACH = 0.1  # pause at the grasp pose before closing [s]
CLOSE_DURATION = 0.6  # [s]
LIFT_DURATION = 1.0  # the shortest lift [s]
HOLD_DURATION = 0.5  # [s]
SLIP_RISE = 0.02  # an object that rose this much but not LIFT_HEIGHT slipped [m]
CLOSED_ON_NOTHING = 0.002  # finger position below which the jaws met nothing [m]

CLOSED_ON_NOTHING_TEXT = "closed on nothing"
OBJECT_SLIPPED_TEXT = "object slipped"
NOT_LIFTED_TEXT = "not lifted"


def judge_lift(rise: float, finger_position: float) -> str | None:
    """None for a successful lift (the object rose LIFT_HEIGHT), else the execution failure mode."""
    if rise >= LIFT_HEIGHT:
        return None
    if rise >= SLIP_RISE:
        return OBJECT_SLIPPED_TEXT
    return CLOSED_ON_NOTHING_TEXT if finger_position < CLOSED_ON_NOTHING else NOT_LIFTED_TEXT


class TrialOutcome(enum.IntEnum):
    """How a grasp trial ended; stored as uint8 codes in the data shards."""

    SUCCESS = 0
    COLLIDES_ON_APPROACH = 1
    CLOSED_ON_NOTHING = 2
    OBJECT_SLIPPED = 3
    NOT_LIFTED = 4

    @property
    def text(self) -> str:
        return OUTCOME_TEXT[self]

    @staticmethod
    def from_judgement(failure: str | None) -> TrialOutcome:
        """The outcome of a trial that reached its grasp pose, from `judge_lift`'s answer."""
        return next(o for o, text in OUTCOME_TEXT.items() if text == (failure or "success"))


OUTCOME_TEXT = {
    TrialOutcome.SUCCESS: "success",
    TrialOutcome.COLLIDES_ON_APPROACH: "hand collides on approach",
    TrialOutcome.CLOSED_ON_NOTHING: CLOSED_ON_NOTHING_TEXT,
    TrialOutcome.OBJECT_SLIPPED: OBJECT_SLIPPED_TEXT,
    TrialOutcome.NOT_LIFTED: NOT_LIFTED_TEXT,
}
