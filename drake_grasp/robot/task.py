"""The grasping task's named constants and its success rule, shared by trials and the closed loop.

One attempt (paper Sec. IV-D): the open hand approaches from `PREGRASP_DISTANCE`
back along the approach axis, closes for `CLOSE_DURATION`, lifts `LIFT_TRAVEL`
in `LIFT_DURATION` and holds for `HOLD_DURATION`. It succeeds, as a robot would
judge it, when the object ends at least `LIFT_HEIGHT` higher **and** is in the
hand: the fingers stopped short of their closed stop and both touch it. The
self-supervised trials that label the stability CNN and the closed loop judge with
the same `judge_grasp`, so a label means the same thing in both.

A scenario may judge by the grasping field's rule instead (`SUCCESS_RULES`, `Scenario.success_rule`):
"held", success when the hand still holds the object after the lift (it touches both fingers and the
jaws are apart), as VGN's simulation judges it (after a 10 cm lift, the gripper touches an object and is
more than a tenth open) and GIGA and Edge Grasp, which run that simulation, count it. An object held
by its rim hangs below the hand and its centre rises less than `LIFT_HEIGHT`: a success by that rule, a
slip by the paper's.
"""

from __future__ import annotations

import enum

# The grasp candidates' samplers (`policy.sampling.sample_candidates`); a stored trial's `trial_sampler`
# is its index here ("mixed": one of a mixed job's two, not told which)
SAMPLERS = ("uniform", "gpg", "mixed", "topdown")
PREGRASP_DISTANCE = 0.10  # hand retreat along -z of G before the approach [m]
LIFT_HEIGHT = 0.15  # success requires the object this much higher [m]
LIFT_TRAVEL = 0.20  # the hand rises this much, so that a held object, even pivoting, clears LIFT_HEIGHT [m]
APPROACH_DURATION = 0.8  # the shortest pre-grasp -> grasp motion [s]
SETTLE_AFTER_APPROACH = 0.1  # pause at the grasp pose before closing [s]
CLOSE_DURATION = 0.6  # [s]
LIFT_DURATION = 1.0  # the shortest lift [s]
PUSH_LENGTH = 0.10  # a push (VPG's other primitive) travels this far along +x_G [m]
PUSH_RISE = 0.10  # and the hand rises this far at its end [m]
HOLD_DURATION = 0.5  # [s]
SLIP_RISE = 0.02  # an object that rose this much but not LIFT_HEIGHT slipped [m]
EMPTY_CLOSE_CHECK = 0.1  # from this long into the close, fingers that met end the grasp at once [s]

DIVERGED = "simulation diverged"  # an attempt or trial whose physics blew up (`simulation.divergence`)
CLOSED_ON_NOTHING_TEXT = "closed on nothing"
OBJECT_SLIPPED_TEXT = "object slipped"
NOT_LIFTED_TEXT = "not lifted"
NOT_IN_HAND_TEXT = "not in the hand"

# How a grasp is judged: "lifted" (the paper's: `LIFT_HEIGHT` higher and in the hand) or "held" (the
# field's benchmark: in the hand after the lift, risen at least `SLIP_RISE`)
SUCCESS_RULES = ("lifted", "held")


def judge_grasp(rise: float, jaws_met: bool, in_hand: bool, rule: str = "lifted") -> str | None:
    """None for a successful grasp, else the execution failure mode.

    `rise`: how much higher the object ended; `jaws_met`: the jaws closed on nothing by the end of the
    hold (`HandSpec.jaws_met`); `in_hand`: the object touches both fingers; `rule`: one of
    `SUCCESS_RULES`. An object that rose without being held (pushed up, balanced on the hand) is a failure.
    """
    if rule not in SUCCESS_RULES:
        raise ValueError(f"unknown success rule '{rule}'; choose one of: {', '.join(SUCCESS_RULES)}")
    if rule == "held" and SLIP_RISE <= rise < LIFT_HEIGHT and in_hand and not jaws_met:
        return None
    if rise >= LIFT_HEIGHT:
        return None if in_hand and not jaws_met else NOT_IN_HAND_TEXT
    if rise >= SLIP_RISE:
        return OBJECT_SLIPPED_TEXT
    return CLOSED_ON_NOTHING_TEXT if jaws_met else NOT_LIFTED_TEXT


class TrialOutcome(enum.IntEnum):
    """How a grasp trial ended; stored as uint8 codes in the data shards."""

    SUCCESS = 0
    COLLIDES_ON_APPROACH = 1
    CLOSED_ON_NOTHING = 2
    OBJECT_SLIPPED = 3
    NOT_LIFTED = 4
    NOT_IN_HAND = 5
    DIVERGED = 6  # the simulation diverged (a failure: no grasp that blows up the physics is kept)

    @property
    def text(self) -> str:
        return OUTCOME_TEXT[self]

    @staticmethod
    def from_judgement(failure: str | None) -> TrialOutcome:
        """The outcome of a trial that reached its grasp pose, from `judge_grasp`'s answer."""
        return next(o for o, text in OUTCOME_TEXT.items() if text == (failure or "success"))


OUTCOME_TEXT = {
    TrialOutcome.SUCCESS: "success",
    TrialOutcome.COLLIDES_ON_APPROACH: "hand collides on approach",
    TrialOutcome.CLOSED_ON_NOTHING: CLOSED_ON_NOTHING_TEXT,
    TrialOutcome.OBJECT_SLIPPED: OBJECT_SLIPPED_TEXT,
    TrialOutcome.NOT_LIFTED: NOT_LIFTED_TEXT,
    TrialOutcome.NOT_IN_HAND: NOT_IN_HAND_TEXT,
    TrialOutcome.DIVERGED: DIVERGED,
}
