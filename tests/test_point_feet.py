"""Point feet in closed loop: Bolt (ODRI's point-foot biped) steps in place, then walks forward."""

from closed_loop_bounds import check
from walk_support import check_mean_error

from romoco_drake.metrics import heading_velocity
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario, with_overrides


def test_bolt_steps_in_place_then_walks_forward_at_the_command():
    """A point-foot robot has no support area, so it steps in place from the start (a zero command
    for 0.3 s), then walks at 0.2 m/s: no fall, and the forward velocity is tracked once the
    scenario's velocity trim has learned Bolt's overshoot (0.235 m/s untrimmed; the trim's first
    strides are at 1-2 s)."""
    scenario = with_overrides(load_scenario("bolt_walk"), command="0:0,0,0;0.3:0.2,0,0")
    logs = {}

    def keep_velocity(built, context):
        log = built.state_log.FindLog(context)
        times = log.sample_times()
        logs["v"] = heading_velocity(built.robot, times, log.data())[times > 2.3].mean(axis=0)

    summary = run_scenario(scenario, duration=3.5, inspect=keep_velocity)
    assert summary["fell"] is False, summary
    check("point_feet.bolt.steps", summary["steps"])
    check("point_feet.bolt.vx_rms", summary["velocity_rms_error"][0])
    v = logs["v"]  # over the last six steps (a whole number of lateral sways)
    check_mean_error("point_feet.bolt.forward", abs(v[0] - 0.2) / 0.2)
    check("point_feet.bolt.vy_mean", abs(v[1]))
