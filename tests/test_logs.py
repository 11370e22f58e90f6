"""Run logs spilled to disk on long runs read back as if they had stayed in memory."""

import numpy as np

import romoco_drake.simulation as simulation
from romoco_drake.runner import run_scenario
from romoco_drake.scenario import load_scenario


def test_spilled_logs_give_the_same_summary_and_samples(monkeypatch):
    """A run whose logs are spilled every 0.4 s has the summary and the samples of one kept in
    memory; the logs in memory hold only what came after the last spill."""
    scenario = load_scenario("g1_walk")
    kept, spilled = {}, {}

    def keep(into):
        def inspect(built, context):
            into["states"] = built.logs.find(built.state_log, context).data().copy()
            into["ticks"] = built.logs.find(built.walking.tick_log, context).sample_times().copy()
            into["in_memory"] = built.state_log.FindLog(context).num_samples()
        return inspect

    plain = run_scenario(scenario, duration=1.5, inspect=keep(kept))
    monkeypatch.setattr(simulation, "SPILL_PERIOD_S", 0.4)
    spilling = run_scenario(scenario, duration=1.5, inspect=keep(spilled))
    for key in ("velocity_rms_error", "mean_velocity", "steps", "fell", "base_height_drift_m"):
        assert spilling[key] == plain[key]
    assert spilling["controller_tick_ms"].keys() == plain["controller_tick_ms"].keys()
    np.testing.assert_array_equal(spilled["states"], kept["states"])
    np.testing.assert_array_equal(spilled["ticks"], kept["ticks"])
    assert kept["in_memory"] == kept["states"].shape[1] > 100
    assert spilled["in_memory"] < 40  # 0.3 s of 100 Hz samples after the last spill at 1.2 s
