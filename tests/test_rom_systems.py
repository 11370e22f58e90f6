"""The ROM planner systems: FootPlacementPlanner against its law, the hybrid LIP template (its
outputs, one step against the S2S maps, closed-loop walking), and the command source."""

import dataclasses
import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from romoco_drake.bench.rom import profile_segments, run_template, segment_metrics, stride_velocities
from romoco_drake.errors import RomocoError
from romoco_drake.planners.command import CommandSegment, CommandSource
from romoco_drake.planners.foot_placement import FootPlacementPlanner
from romoco_drake.planners.template import GaitState, HybridLipTemplate
from romoco_drake.rom.hlip import hlip_s2s
from romoco_drake.rom.lip import ss_flow
from romoco_drake.rom.mlip import mlip_s2s
from romoco_drake.rom.planners import PlannerParams, foot_placement_laws, make_planner
from romoco_drake.rom.types import PlannerOutput, WalkCommand

MASS = 30.0
T_DS = 0.1
BASE = WalkCommand(step_width=0.2, com_height=0.65, step_time=0.3)
PROFILE = ((0.0, 0.0, 0.0), (2.0, 0.4, 0.0))  # (start s, vx, vy): stand, then walk forward
DURATION = 5.0


def _rot(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def _assert_same_plan(a: PlannerOutput, b: PlannerOutput) -> None:
    for field in dataclasses.fields(PlannerOutput):
        np.testing.assert_array_equal(getattr(a, field.name), getattr(b, field.name), err_msg=field.name)


@pytest.mark.parametrize("name", foot_placement_laws())
def test_planner_system_output_is_the_law(name):
    params = PlannerParams(mass=MASS, t_ds=T_DS)
    system = FootPlacementPlanner(make_planner(name, params))
    law = make_planner(name, params)
    context = system.CreateDefaultContext()
    cmd = WalkCommand(vx=0.35, vy=-0.1, wz=0.2, com_height=0.7, step_time=0.35)
    system.command_port.FixValue(context, cmd.to_vector())
    state = np.array([0.03, -0.06, 0.7, -2.5, 6.0, 0.2])
    nan_state = np.where(np.arange(6) == 4, np.nan, state)
    for sign, side, t_in, rom_state in ((1.0, "left", 0.1, state), (-1.0, "right", 0.27, state),
                                        (1.0, "left", 0.1, nan_state)):
        system.rom_state_port.FixValue(context, rom_state)
        system.gait_phase_port.FixValue(context, [sign, t_in])
        plan = system.planner_output_port.Eval(context)
        assert plan.valid == bool(np.isfinite(rom_state).all())
        _assert_same_plan(plan, law.plan(rom_state, side, t_in, cmd))


def _template(ds_model: str, stance=(0.3, -0.1), heading=0.4, z0=0.7, t_ss=0.3, t_ds=0.0):
    gait = GaitState(side="right", stance=stance, heading=heading, step_start=0.0, t_ss=t_ss,
                     t_ds=t_ds, z0=z0, landed=None, steps=3)
    return HybridLipTemplate(MASS, ds_model, gait, np.zeros(4))


def test_template_outputs_match_their_definitions():
    """rom_state is the CoM and L = m p × ċ (ż = 0) about the stance, in the stance yaw frame."""
    z0, heading, stance = 0.7, 0.4, np.array([0.3, -0.1])
    template = _template("hold_velocity", tuple(stance), heading, z0)
    context = template.CreateDefaultContext()
    context.SetTime(0.12)
    com = np.array([0.35, -0.2, 0.4, -0.3])
    context.SetContinuousState(com)
    rot_t = _rot(heading).T
    p = np.array([*(rot_t @ (com[:2] - stance)), z0])
    v = np.array([*(rot_t @ com[2:]), 0.0])
    rom_state = template.rom_state_port.Eval(context)
    np.testing.assert_allclose(rom_state, [*p, *(MASS * np.cross(p, v))], atol=1e-12)
    np.testing.assert_allclose(template.gait_phase_port.Eval(context), [-1.0, 0.12])
    np.testing.assert_array_equal(template.com_port.Eval(context), com)
    np.testing.assert_allclose(template.support_port.Eval(context), [*stance, heading, 3.0, -1.0])


@pytest.mark.parametrize(("ds_model", "t_ds", "s2s"), [
    ("none", 0.0, hlip_s2s), ("hold_velocity", 0.1, hlip_s2s), ("zmp_ramp", 0.1, mlip_s2s),
])
def test_template_step_is_the_s2s_map(ds_model, t_ds, s2s):
    """SS, touchdown at the planned point, DS per ds_model, support switch, SS: the pre-impact
    state (both planes, stance yaw frame) moves by the model's S2S map."""
    z0, t_ss, heading, stance = 0.7, 0.3, 0.4, np.array([0.3, -0.1])
    template = _template(ds_model, tuple(stance), heading, z0, t_ss, t_ds)
    context = template.CreateDefaultContext()
    planes = np.array([[-0.05, z0 * 0.4], [0.08, z0 * -0.3]])  # (p, L/m) sagittal, lateral
    com = [*(stance + _rot(heading) @ planes[:, 0]), *(_rot(heading) @ planes[:, 1] / z0)]
    context.SetContinuousState(com)
    u = np.array([0.15, 0.22])
    nan = np.full((2, 2), np.nan)
    plan = PlannerOutput("test", "right", np.array([*u, 0.0]), 0.0, t_ss, t_ds, t_ss, z0, nan, nan, u)
    template.planner_output_port.FixValue(context, plan)
    template.command_port.FixValue(context, WalkCommand(com_height=z0, step_time=t_ss).to_vector())
    simulator = Simulator(template, context)
    simulator.get_mutable_integrator().set_target_accuracy(1e-11)
    simulator.AdvanceTo(2 * t_ss + t_ds)
    assert template.support_port.Eval(context)[3] == 4  # one support switch, the next not yet
    rom_state = template.rom_state_port.Eval(context)
    pre = planes @ ss_flow(t_ss, z0).T
    step = s2s(z0, t_ss, t_ds)
    expected = [step.step(x, ui) for x, ui in zip(pre, u, strict=True)]
    actual = [[rom_state[0], rom_state[4] / MASS], [rom_state[1], -rom_state[3] / MASS]]
    np.testing.assert_allclose(actual, expected, atol=1e-7)


def test_template_takes_z0_from_the_command_at_the_support_switch():
    template = _template("none", z0=0.7, t_ss=0.3)
    context = template.CreateDefaultContext()
    plan = make_planner("alip", PlannerParams(mass=MASS)).plan(np.zeros(6), "right", 0.0, BASE)
    template.planner_output_port.FixValue(context, plan)
    template.command_port.FixValue(context, WalkCommand(com_height=0.9, step_time=0.4).to_vector())
    Simulator(template, context).AdvanceTo(0.3 + 1e-3)
    gait = template.gait(context)
    assert gait.steps == 4 and gait.t_ss == 0.4
    assert gait.z0 == 0.9


@pytest.fixture(scope="module", params=foot_placement_laws())
def walk(request):
    """(name, segments, run, stride times, stride velocities) of a planner walking PROFILE."""
    planner = FootPlacementPlanner(make_planner(request.param, PlannerParams(mass=MASS, t_ds=T_DS)))
    segments = profile_segments(BASE, PROFILE)
    run = run_template(planner, MASS, segments, DURATION)
    return request.param, segments, run, *stride_velocities(run)


def test_template_walk_converges_to_the_command(walk):
    name, segments, _, times, vel = walk
    rows = segment_metrics(segments, DURATION, times, vel)
    assert [r["command"] for r in rows] == [[0.0, 0.0], [0.4, 0.0]]
    for row in rows:
        assert row["steps_to_converge"] is not None and row["steps_to_converge"] <= 5, (name, row)
    np.testing.assert_allclose(vel[-1], [0.4, 0.0], atol=0.02)


def test_template_walk_stays_over_its_feet(walk):
    _, _, run, _, _ = walk
    offset = run.com[:2] - run.support[:2]
    assert np.max(np.linalg.norm(offset, axis=0)) < 0.35  # observed ≤ 0.24 m
    assert np.max(np.abs(run.com[2:])) < 1.0  # observed ≤ 0.63 m/s


def test_template_walk_alternates_sides(walk):
    name, _, run, _, _ = walk
    law_t_ds = make_planner(name, PlannerParams(mass=MASS, t_ds=T_DS)).t_ds
    steps, side = run.support[3], run.support[4]
    switches = np.flatnonzero(np.diff(steps))
    assert len(switches) == math.floor(DURATION / (BASE.step_time + law_t_ds) + 1e-6)
    assert np.all(np.diff(steps)[switches] == 1)
    assert np.all(side[switches + 1] == -side[switches])
    # With v_y = 0 the new foot lands on the far side: right of a left stance and vice versa.
    dy = run.support[1, switches + 1] - run.support[1, switches]
    assert np.all(np.sign(dy) == -side[switches])


def test_command_source_outputs_the_latest_segment():
    cmds = [WalkCommand(), WalkCommand(vx=0.5), WalkCommand(vy=-0.2, step_time=0.4)]
    source = CommandSource([CommandSegment(t, c) for t, c in zip((0.0, 1.5, 3.0), cmds, strict=True)])
    context = source.CreateDefaultContext()
    for t, expected in ((0.0, 0), (1.0, 0), (1.5, 1), (2.999, 1), (3.0, 2), (100.0, 2)):
        context.SetTime(t)
        np.testing.assert_array_equal(source.command_port.Eval(context), cmds[expected].to_vector())
        assert source.command_at(t) == cmds[expected]


def test_command_source_rejects_bad_profiles():
    a, b = CommandSegment(0.0, WalkCommand()), CommandSegment(1.0, WalkCommand(vx=0.3))
    for segments, match in (([], "starting at t = 0"), ([b], "starting at t = 0"),
                            ([a, b, CommandSegment(0.5, WalkCommand())], "time order")):
        with pytest.raises(RomocoError, match=match):
            CommandSource(segments)


def test_template_ends_a_step_at_an_adapted_step_time():
    """A plan with adapted timing (step adaptation) lands the foot at its own T_SS, not the command's."""
    template = _template("none", z0=0.7, t_ss=0.3)
    context = template.CreateDefaultContext()
    plan = make_planner("alip", PlannerParams(mass=MASS)).plan(np.zeros(6), "right", 0.0, BASE)
    template.planner_output_port.FixValue(context, dataclasses.replace(plan, t_ss=0.22, timing_adapted=True))
    template.command_port.FixValue(context, WalkCommand(com_height=0.7, step_time=0.3).to_vector())
    Simulator(template, context).AdvanceTo(0.22 + 1e-3)
    assert template.gait(context).steps == 4
