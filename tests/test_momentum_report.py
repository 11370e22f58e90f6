"""Momentum report of the XO paper (Fig. 5-9): metrics on synthetic momentum logs, and the figures."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from romoco_drake.control.momentum_log import MOMENTUM_LOG_SIZE, MomentumRecord, momentum_summary
from romoco_drake.plots import _frontal_orbits, plot_momentum_run
from romoco_drake.rom import alip_general
from romoco_drake.spatial import GRAVITY

DT = 0.1
WALK = (0.2, 0.0)
STOP = (0.0, 0.0)
MASS, HEIGHT, T_STEP, WIDTH = 150.0, 1.0, 0.5, 0.4


def _column(stance=0, t_in_step=0.0, cmd=WALK, l_com=(0.0, 0.0, 0.0), l_c=(math.nan,) * 3,
            pred=(math.nan,) * 2) -> np.ndarray:
    return MomentumRecord(stance, t_in_step, np.array(cmd), l_com=np.array(l_com), l_contact=np.array(l_c),
                          l_contact_predicted=np.array(pred)).pack()


def _double_support() -> list[np.ndarray]:
    """Out of single support: huge centroidal momentum that must not leak into any number."""
    return [_column(0, 0.0, WALK, l_com=(1e3, 1e3, 1e3))]


def _step(stance, l_end, pred_mid, n=5, cmds=None) -> list[np.ndarray]:
    """n samples of one step; the prediction is ``pred_mid`` only at the first sample with t ≥ nDT/2
    (sample 3 of 5, sample 2 of 4), and 100 off everywhere else; L_c is ``l_end`` at the last sample."""
    mid = math.ceil(n / 2)
    cmds = cmds or [WALK] * n
    return [_column(stance, k * DT, cmds[k], l_c=(*l_end, 7.0) if k == n - 1 else (1.0, 1.0, 0.0),
                    pred=pred_mid if k == mid else (pred_mid[0] + 100.0, pred_mid[1] - 100.0))
            for k in range(n)]


def _log(columns: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    return np.arange(len(columns)) * DT, np.column_stack(columns)


def test_record_packs_and_unpacks_by_name():
    """Every row belongs to one field: a log unpacks to the record it was packed from, per column."""
    data = np.arange(2.0 * MOMENTUM_LOG_SIZE).reshape(MOMENTUM_LOG_SIZE, 2)
    assert MOMENTUM_LOG_SIZE == 26 and MomentumRecord().pack().shape == (MOMENTUM_LOG_SIZE,)
    for k in range(2):
        np.testing.assert_array_equal(MomentumRecord.unpack(data[:, k]).pack(), data[:, k])
    log = MomentumRecord.unpack(data)
    np.testing.assert_array_equal(log.stance, data[0])
    np.testing.assert_array_equal(log.l_contact_predicted, data[24:26])


def test_centroidal_ratio_over_walking_single_support_only():
    times, data = _log(_double_support() + [
        _column(1, 0.0, WALK, l_com=(3.0, 4.0, 0.0), l_c=(0.0, 30.0, 40.0)),
        _column(1, 0.1, (0.0, -0.2), l_com=(0.0, 0.0, 1.0), l_c=(10.0, 0.0, 0.0)),
        _column(-1, 0.0, STOP, l_com=(50.0, 0.0, 0.0), l_c=(1.0, 0.0, 0.0)),  # no command
    ])
    # sqrt((25 + 1) / 2) / sqrt((2500 + 100) / 2)
    assert momentum_summary(times, data)["centroidal_am_ratio"] == 0.1


def _walk(offset=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Two scored steps (|L_c| 10 and 20 at their ends, predictions ``offset`` off at mid-step)
    among steps that must not count: a zero command, a command dropped for one sample, the log's end."""
    def pred(l_end):
        return (l_end[0] + offset[0], l_end[1] + offset[1])

    return _log(_double_support()
                + _step(1, (6.0, 8.0), pred((6.0, 8.0)))
                + _step(1, (0.0, 20.0), pred((0.0, 20.0)), n=4)  # same stance: t_in_step goes back
                + _double_support()
                + _step(-1, (1.0, 1.0), (9.0, 9.0), cmds=[STOP] * 5)
                + _step(1, (1.0, 1.0), (9.0, 9.0), cmds=[WALK] * 4 + [STOP])
                + _step(-1, (5.0, 5.0), (5.0, 5.0))
                + _step(1, (1.0, 1.0), (9.0, 9.0), n=3))  # cut off by the end of the log


def test_exact_mid_step_predictions_score_zero():
    summary = momentum_summary(*_walk())
    assert summary["step_end_L_error"] == 0.0
    assert summary["step_end_L_steps"] == 3


def test_known_prediction_offset_gives_its_ratio():
    times, data = _walk(offset=(3.0, 4.0))
    # steps: |(3, 4)| = 5 off at |L_c| 10 and 20, exact at |(5, 5)|: (5 + 5 + 0) / (10 + 20 + √50)
    assert momentum_summary(times, data)["step_end_L_error"] == round(10.0 / (30.0 + math.sqrt(50.0)), 4)


def test_nothing_qualifies_gives_none():
    standing = _log(_double_support() * 5)
    assert momentum_summary(*standing) == {"centroidal_am_ratio": None, "step_end_L_error": None,
                                           "com_lateral_rms_error": None, "com_height_rms_error": None,
                                           "momentum_tracking_error": None, "vertical_momentum_ratio": None,
                                           "step_end_L_steps": 0}
    in_place = _log(_step(1, (6.0, 8.0), (6.0, 8.0), cmds=[STOP] * 5) + _double_support())
    assert momentum_summary(*in_place)["centroidal_am_ratio"] is None
    cut_off = momentum_summary(*_log(_double_support() + _step(1, (6.0, 8.0), (6.0, 8.0))))
    assert cut_off["step_end_L_error"] is None and cut_off["step_end_L_steps"] == 0
    assert cut_off["centroidal_am_ratio"] == 0.0


def test_frontal_orbits_start_at_eq18_offset_and_follow_eq10():
    """Each stance's orbit, started by inverting M_y(T), begins at the offset planned in the other
    stance, ends at (p* + vy T, L_cx^d) and is the flow of eq. 10 (checked by integration)."""
    vy, t = -0.2, np.linspace(0.0, T_STEP, 60)
    fig, ax = plt.subplots()
    _frontal_orbits(ax, vy, t, MASS, HEIGHT, WIDTH)
    mh = MASS * HEIGHT
    for line, planned_in in zip(ax.lines, ("left", "right"), strict=True):
        p, l_cx = line.get_xydata().T
        p_start = alip_general.lateral_offset(vy, T_STEP, WIDTH, planned_in)
        assert p[0] == pytest.approx(p_start, abs=1e-12)
        assert (p[-1], l_cx[-1]) == pytest.approx(
            (p_start + vy * T_STEP, alip_general.desired_momentum_x(p_start, vy, T_STEP, MASS, HEIGHT)))
        flow = solve_ivp(lambda _, y: [-y[1] / mh, -MASS * GRAVITY * y[0]], (0.0, T_STEP), [p[0], l_cx[0]],
                         t_eval=t, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(flow.y, [p, l_cx], rtol=1e-7, atol=1e-9)
    plt.close(fig)


@pytest.mark.parametrize("step_width", [WIDTH, None])
def test_plot_momentum_run_writes_five_figures(tmp_path, step_width):
    rng = np.random.default_rng(0)
    cmds = [(0.2, 0.0)] * 20 + [(0.0, 0.1)] * 20 + [STOP] * 10
    columns = _double_support()
    for k in range(0, 50, 5):
        columns += _step(1 if k % 10 else -1, rng.normal(size=2), rng.normal(size=2), cmds=cmds[k:k + 5])
    times, data = _log(columns)
    log = MomentumRecord.unpack(data)
    for rows in (log.com, log.com_desired, log.momentum, log.momentum_desired, log.com_in_contact):
        rows[:] = rng.normal(size=rows.shape)  # views into data
    wanted = np.column_stack([log.command.T, np.zeros(len(times))])
    paths = plot_momentum_run(tmp_path / "figs", "xo", times, data, MASS, HEIGHT, T_STEP, times,
                              wanted + 0.01, wanted, step_width=step_width)
    assert [p.name for p in paths] == ["xo_fig5_com.png", "xo_fig6_momentum.png", "xo_fig7_phase.png",
                                       "xo_fig8_contact_momentum.png", "xo_fig9_velocity.png"]
    assert all(p.stat().st_size > 0 for p in paths)


def _orbit_step(stance: int, p0: float, l0: float, n: int = 25, dt: float = 0.02, bump: float = 0.0
                ) -> list[np.ndarray]:
    """One single-support step on the exact sagittal and frontal ALIP flows (eq. 9-10) from
    (p0, L0) in both planes; ``bump`` adds that much to L_cy at the step's middle sample."""
    ell = math.sqrt(GRAVITY / HEIGHT)
    cols = []
    for k in range(n):
        t = k * dt
        p = p0 * math.cosh(ell * t) + l0 * math.sinh(ell * t) / (MASS * HEIGHT * ell)
        lc = l0 * math.cosh(ell * t) + MASS * HEIGHT * ell * p0 * math.sinh(ell * t)
        l_y = lc + (bump if k == n // 2 else 0.0)
        record = MomentumRecord(stance, t, np.array(WALK), l_com=np.zeros(3),
                                l_contact=np.array([-lc, l_y, 0.0]), com_in_contact=np.array([p, -p]))
        cols.append(record.pack())
    return cols


def test_orbit_spread_is_zero_on_the_template_and_grows_off_it():
    """Fig. 7's number: states on the ALIP flow keep e = L²/(m² g H) − p² (spread 0); a momentum
    kick mid-step moves them off the orbit, in the sagittal plane only."""
    steps = [_orbit_step(1 if k % 2 else -1, -0.1, 25.0, dt=0.02) for k in range(6)]
    columns = [c for step in steps for c in step]
    times = np.arange(len(columns)) * 0.02
    data = np.column_stack(columns)
    s = momentum_summary(times, data, MASS, HEIGHT)
    # Six 0.5 s steps: the first two start within SETTLE_S of the log's start (a transition), the
    # last may be cut off by the log's end; three are scored.
    assert s["alip_orbit_steps"] == 3
    assert s["alip_orbit_spread"][0] < 1e-3 and s["alip_orbit_spread"][1] < 1e-3
    kicked = [_orbit_step(1 if k % 2 else -1, -0.1, 25.0, dt=0.02, bump=20.0) for k in range(6)]
    s = momentum_summary(times, np.column_stack([c for step in kicked for c in step]), MASS, HEIGHT)
    assert s["alip_orbit_spread"][0] > 0.05 and s["alip_orbit_spread"][1] < 1e-3
    assert "alip_orbit_spread" not in momentum_summary(times, data)  # needs the mass and height
