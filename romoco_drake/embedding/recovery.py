"""The push-recovery latch the embedding keeps over a recovery's steps (:attr:`SwingState.recovery`).

A recovery is the run of ticks whose plan the step adapter bounded (``PlannerOutput.step_bounded``).
Its latch is (stance side of its first step, whether the law asked that step to cross the stance
foot (``PlannerOutput.step_across``), steps begun since). When that first step could not go toward
the push, stepping has lost a step, and the upper body helps (:attr:`TaskReferences.upper_body`, the
TSC-QP's ``locked_hold.recovery``) for that step and the next, which catches the push.

Why only two steps: held over the whole recovery, G1 pushed 20 N·s to the left as its left foot took
the weight (``romoco bench push`` cell left/0) fell into a sideways gait at 0.9 m/s, every step bounded
at its shortest time, the latch never clearing, and fell 6 s after the push; over two steps it
walks on at its command 2 s after the push, at 20 and at 30 N·s (three steps: the sideways gait again).
"""

from __future__ import annotations

from romoco_drake.rom.types import PlannerOutput

UPPER_BODY_STEPS = 2  # steps of a recovery the upper body helps (module docstring)


def next_recovery(recovery: tuple[str, bool, int] | None, stance_side: str, plan: PlannerOutput,
                  new_step: bool = False) -> tuple[str, bool, int] | None:
    """:attr:`SwingState.recovery` after a tick on ``stance_side`` following ``plan`` (``new_step``: the
    tick begins a step): it begins with the first bounded plan and ends with an unbounded one; a step
    across the stance foot counts only in its first step (a later one, after a push late in a swing,
    is the stepping's own to catch)."""
    if not plan.step_bounded:
        return None
    if recovery is None:
        return stance_side, plan.step_across, 0
    first, across, steps = recovery
    steps += new_step
    return first, across or (plan.step_across and steps == 0), steps


def upper_body_helps(recovery: tuple[str, bool, int] | None) -> bool:
    """Whether the upper body helps the recovery (:attr:`TaskReferences.upper_body`): it began with a
    step across, and only in that step and the next, which catches the push (UPPER_BODY_STEPS)."""
    return recovery is not None and recovery[1] and recovery[2] < UPPER_BODY_STEPS
