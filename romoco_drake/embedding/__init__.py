"""Output embedding math: task outputs, swing trajectories, contact constraints and force limits.

Plain classes and functions on the controller plant and numpy arrays; the LeafSystem that
turns planner outputs into task references wraps them.
"""

from romoco_drake.embedding.bezier import BezierCurve, SwingTrajectory, plan_swing, quintic_bezier
from romoco_drake.embedding.contact import (
    DOMAINS,
    ContactModel,
    FootContact,
    select_contact_points,
    support_halfplanes,
)
from romoco_drake.embedding.outputs import (
    InAirOutputs,
    LegJoints,
    Output,
    StandingOutputs,
    WalkingOutputs,
    find_leg_joints,
    sole_frame,
)

__all__ = [
    "DOMAINS",
    "BezierCurve",
    "ContactModel",
    "FootContact",
    "InAirOutputs",
    "LegJoints",
    "Output",
    "StandingOutputs",
    "SwingTrajectory",
    "WalkingOutputs",
    "find_leg_joints",
    "plan_swing",
    "quintic_bezier",
    "select_contact_points",
    "sole_frame",
    "support_halfplanes",
]
