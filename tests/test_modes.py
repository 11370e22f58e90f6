"""The typed contracts between systems: link stages on vector ports, counters on abstract ports."""

import math

import numpy as np
import pytest

from romoco_drake.modes import ControllerStats, LinkCounters, LinkStage, RobotLinkCounters


def test_link_stage_decodes_its_numbers_and_orders_by_loss():
    assert [LinkStage.decode(float(s)) for s in LinkStage] == list(LinkStage)
    assert LinkStage.FRESH < LinkStage.RIDE_THROUGH < LinkStage.STAND < LinkStage.DAMPING
    assert LinkStage.FRESH < LinkStage.HOLD < LinkStage.DAMPING
    for bad in (-1.0, 0.5, 7.0, math.nan):
        with pytest.raises(ValueError, match="is not a link stage"):
            LinkStage.decode(bad)


def test_counters_round_trip_through_discrete_state_and_add_by_name():
    stats = ControllerStats(failures=3, safe_ticks=2, failure_streak=1, relaxed_ticks=4)
    assert ControllerStats.size() == 4
    assert ControllerStats.from_vector(stats.vector()) == stats
    total = LinkCounters(stale_events=1, rejected_messages=2) + LinkCounters(rejected_messages=1, estop=1)
    assert total.summary() == {"stale_events": 1, "ride_through_events": 0, "stand_events": 0,
                               "damping_events": 0, "rejected_messages": 3, "clamped_commands": 0, "estop": 1}
    assert total.entered(LinkStage.STAND).stand_events == 1
    np.testing.assert_array_equal(RobotLinkCounters(hold_events=True).vector(), [0, 1, 0, 0, 0])
