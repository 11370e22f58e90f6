"""What a momentum-controlled run records each tick: the XO paper's momenta, references and predictions.

:class:`MomentumLog` samples, at the controller's tick and from the tick's shared evaluation,
the numbers behind the paper's Figs. 5-9 and the run summary's ``centroidal_am_ratio`` and
``step_end_L_error`` (:func:`~romoco_drake.metrics.momentum_summary`); the row layout is
:data:`~romoco_drake.metrics.MOMENTUM_LOG_SIZE` and the index constants next to it.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from romoco_drake.control.tasks import placeholder_references
from romoco_drake.embedding.references import TaskReferences
from romoco_drake.metrics import MOMENTUM_LOG_SIZE
from romoco_drake.modes import Mode
from romoco_drake.robots.kinematics import RobotKinematics, kinematics_model_value
from romoco_drake.robots.model import RobotModel
from romoco_drake.rom.types import COMMAND_SIZE, ROM_STATE_SIZE, PlannerOutput


class MomentumLog(LeafSystem):
    """The momentum controller's record of one tick (module docstring).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``kinematics`` | in | abstract | :class:`~romoco_drake.robots.kinematics.RobotKinematics` of the state |
    | ``task_references`` | in | abstract | :class:`~romoco_drake.embedding.references.TaskReferences` |
    | ``planner_output`` | in | abstract | :class:`~romoco_drake.rom.types.PlannerOutput` |
    | ``command`` | in | 6 | the walking command the planner follows |
    | ``rom_state`` | in | 6 | [p, L_c] about the stance contact frame {c} (the planner's input) |
    | ``record`` | out | 26 | the tick's row (layout in :mod:`romoco_drake.metrics`), held |

    One periodic discrete update every ``period`` s at ``offset``, the controller's tick.
    """

    def __init__(self, robot: RobotModel, period: float, offset: float = 0.0):
        super().__init__()
        self.robot = robot
        self.kinematics_port = self.DeclareAbstractInputPort("kinematics", kinematics_model_value(robot))
        self.task_references_port = self.DeclareAbstractInputPort(
            "task_references", AbstractValue.Make(placeholder_references(robot)))
        self.planner_output_port = self.DeclareAbstractInputPort(
            "planner_output", AbstractValue.Make(PlannerOutput.placeholder()))
        self.command_port = self.DeclareVectorInputPort("command", COMMAND_SIZE)
        self.rom_state_port = self.DeclareVectorInputPort("rom_state", ROM_STATE_SIZE)
        self._record = self.DeclareDiscreteState(np.full(MOMENTUM_LOG_SIZE, np.nan))
        self.record_port = self.DeclareStateOutputPort("record", self._record)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def record(self, kin: RobotKinematics, refs: TaskReferences, plan: PlannerOutput, command: np.ndarray,
               rom_state: np.ndarray) -> np.ndarray:
        """The row for one tick (NaN where a quantity does not apply)."""
        row = np.full(MOMENTUM_LOG_SIZE, np.nan)
        row[2:4] = command[:2]
        if not kin.finite:
            row[:2] = 0.0
            return row
        m = self.robot.total_mass
        A_G, _ = kin.centroidal_momentum_matrix()
        h = A_G @ kin.v
        p = kin.p_com
        row[4:7], row[10:13], row[13:16] = p, h[:3], h[3:]
        for i, name in enumerate(refs.names):
            if name.startswith("com_"):
                axis = "xyz".index(name[-1])
                row[7 + axis] = p[axis] - refs.error[i]
                row[16 + axis] = m * refs.ydot_des[i]
        if refs.com_plan is not None:
            row[7:9], row[16:18] = refs.com_plan[0], m * refs.com_plan[1]
        single = refs.mode == Mode.WALKING and refs.domain.single_support
        if not single:
            row[:2] = 0.0
            return row
        row[0] = 1.0 if refs.stance_side == "left" else -1.0
        row[1] = plan.t_ss - plan.time_to_touchdown
        row[19:22], row[22:24] = rom_state[3:], rom_state[:2]
        if plan.valid and plan.stance_side == refs.stance_side:
            row[24], row[25] = -m * plan.pre_impact[1, 1], m * plan.pre_impact[0, 1]
        return row

    def _update(self, context, discrete_state) -> None:
        row = self.record(self.kinematics_port.Eval(context), self.task_references_port.Eval(context),
                          self.planner_output_port.Eval(context), self.command_port.Eval(context),
                          self.rom_state_port.Eval(context))
        discrete_state.get_mutable_vector(self._record).SetFromVector(row)
