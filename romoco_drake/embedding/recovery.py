"""The push-recovery latch the embedding keeps over a recovery's steps (:attr:`SwingState.recovery`).

A recovery is the run of ticks whose plan the step adapter bounded (``PlannerOutput.step_bounded``).
Its latch is (whether the law asked its first step to cross the stance foot
(``PlannerOutput.step_across``), steps begun since). When that first step could not go toward
the push, stepping has lost a step, and the upper body helps (:attr:`TaskReferences.upper_body`, the
TSC-QP's ``locked_hold.recovery``) for that step and the next, which catches the push.

Why only two steps: held over the whole recovery, G1 pushed 20 N·s to the left as its left foot took
the weight (``romoco bench push`` cell left/0) fell into a sideways gait at 0.9 m/s, every step bounded
at its shortest time, the latch never clearing, and fell 6 s after the push; over two steps it
walks on at its command 2 s after the push, at 20 and at 30 N·s (three steps: the sideways gait again).
On the invariant EKF that cell at 20 N·s still fell into the sideways gait until the step a push
interrupts also ended its sideways swing early (``EmbeddingCore._lateral_end``); it now walks on.
"""

from __future__ import annotations

from romoco_drake.rom.types import PlannerOutput

UPPER_BODY_STEPS = 2  # steps of a recovery the upper body helps (module docstring)


def next_recovery(recovery: tuple[bool, int] | None, plan: PlannerOutput, new_step: bool = False
                  ) -> tuple[bool, int] | None:
    """:attr:`SwingState.recovery` after a tick following ``plan`` (``new_step``: the tick begins a
    step): it begins with the first bounded plan and ends with an unbounded one; a step across the
    stance foot counts only in its first step (a later one, after a push late in a swing, is the
    stepping's own to catch)."""
    if not plan.step_bounded:
        return None
    if recovery is None:
        return plan.step_across, 0
    across, steps = recovery
    steps += new_step
    return across or (plan.step_across and steps == 0), steps


def upper_body_helps(recovery: tuple[bool, int] | None) -> bool:
    """Whether the upper body helps the recovery (:attr:`TaskReferences.upper_body`): it began with a
    step across, and only in that step and the next, which catches the push (UPPER_BODY_STEPS)."""
    return recovery is not None and recovery[0] and recovery[1] < UPPER_BODY_STEPS
