"""PNG figures of walks: template runs, whole-body runs, and the XO paper's momentum report."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from romoco_drake.control.momentum_log import MomentumRecord  # noqa: E402
from romoco_drake.metrics import SETTLE_S  # noqa: E402
from romoco_drake.rom import alip_general  # noqa: E402
from romoco_drake.rom.lip import omega  # noqa: E402
from romoco_drake.spatial import GRAVITY  # noqa: E402

_IDEAL_ORBIT = {"lw": 6.0, "alpha": 0.3, "zorder": 1}  # wide and pale, behind the measured points


def plot_template_run(out_dir: Path, name: str, run, segments, stride_times: np.ndarray,
                      stride_vel: np.ndarray, mass: float) -> list[Path]:
    """Writes ``rom_<name>_velocity.png`` and ``rom_<name>_phase.png``; returns their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    ends = [s.start for s in segments[1:]] + [run.times[-1]]

    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    for axis, (ax, label) in enumerate(zip(axes, ("forward", "lateral"), strict=True)):
        cmd_t = np.array([[s.start, e] for s, e in zip(segments, ends, strict=True)]).ravel()
        cmd_v = np.repeat([[s.command.vx, s.command.vy][axis] for s in segments], 2)
        ax.plot(cmd_t, cmd_v, "k--", lw=1.2, label="command")
        ax.plot(run.times, run.com[2 + axis], color="0.75", lw=0.8, label="CoM velocity")
        ax.plot(stride_times, stride_vel[:, axis], "o-", ms=3, label="stride average")
        ax.set_ylabel(f"{label} velocity [m/s]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    velocity = _save(fig, f"{name}: velocity tracking on the hybrid LIP template",
                     out_dir / f"rom_{name}_velocity.png")

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    planes = (("sagittal", run.rom_state[0], run.rom_state[4] / mass),
              ("lateral", run.rom_state[1], -run.rom_state[3] / mass))
    for ax, (label, p, ell) in zip(axes, planes, strict=True):
        for seg, end in zip(segments, ends, strict=True):
            mask = (run.times >= seg.start) & (run.times < end)
            ax.plot(p[mask], ell[mask], lw=0.9,
                    label=f"{seg.start:g}-{end:g} s: v=({seg.command.vx:g}, {seg.command.vy:g})")
        ax.set_xlabel(f"{label} CoM rel. stance pivot p [m]")
        ax.set_ylabel("L / m [m²/s]")
        ax.set_title(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    phase = _save(fig, f"{name}: phase portraits (jumps are support switches)",
                  out_dir / f"rom_{name}_phase.png")
    return [velocity, phase]


def plot_walking_run(out_dir: Path, name: str, times: np.ndarray, tracking: dict, error_times: np.ndarray,
                     errors: np.ndarray) -> list[Path]:
    """Writes ``<name>_velocity.png`` (command vs measured) and ``<name>_tracking.png``."""
    from romoco_drake.embedding.system import ERROR_GROUPS

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6.5))
    labels = ("forward velocity [m/s]", "lateral velocity [m/s]", "yaw rate [rad/s]")
    for i, (ax, label) in enumerate(zip(axes, labels, strict=True)):
        ax.plot(times, tracking["wanted"][:, i], "k--", lw=1.2, label="command")
        ax.plot(times, tracking["measured"][:, i], lw=1.2, label="measured, 1 s average")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper left", fontsize=8)
    axes[-1].set_xlabel("time [s]")
    velocity = _save(fig, f"{name}: commanded and measured base velocity (heading frame)",
                     out_dir / f"{name}_velocity.png")

    fig, ax = plt.subplots(figsize=(8, 3.8))
    for (label, _), series in zip(ERROR_GROUPS, errors, strict=True):
        if np.any(series > 0.0):
            ax.plot(error_times, series, lw=0.9, label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("|y − y_d| of active outputs [m or rad]")
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    tracking_png = _save(fig, f"{name}: output tracking errors", out_dir / f"{name}_tracking.png")
    return [velocity, tracking_png]


def plot_run(out_dir: Path, name: str, robot, times: np.ndarray, tracking: dict, errors: tuple,
             momentum: tuple | None = None) -> list[Path]:
    """``romoco run --plot``'s figures: the walking plots from the tracking and the (times, data)
    of the error log, and with a momentum log's (times, data) the XO paper's Fig. 5-9."""
    paths = plot_walking_run(out_dir, name, times, tracking, *errors)
    if momentum is not None:
        w = robot.config.walking
        paths += plot_momentum_run(out_dir, name, *momentum, robot.total_mass, w.z0, w.t_ss, times,
                                   tracking["measured"], tracking["wanted"], step_width=w.step_width)
    return paths


def plot_momentum_run(out_dir: Path, name: str, times: np.ndarray, data: np.ndarray, mass: float,
                      com_height: float, step_time: float, tracking_times: np.ndarray,
                      tracking_measured: np.ndarray, tracking_wanted: np.ndarray, *,
                      step_width: float | None = None) -> list[Path]:
    """The XO paper's Fig. 5-9 from a momentum log (a packed :class:`MomentumRecord` per column).

    Writes ``<name>_fig5_com.png``, ``_fig6_momentum.png``, ``_fig7_phase.png``,
    ``_fig8_contact_momentum.png`` and ``_fig9_velocity.png``; returns their paths. Desired is
    dashed red, measured blue. ``tracking_*`` are ``metrics.velocity_tracking``'s times,
    "measured" and "wanted" (N, 3). The frontal ideal orbits of Fig. 7 need the step width W
    (eq. 18); without it only the sagittal ones are drawn.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    log = MomentumRecord.unpack(data)

    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6.5))
    for i, ax in enumerate(axes):
        _desired_measured(ax, times, log.com_desired[i], log.com[i], f"CoM {'xyz'[i]} [m]")
    axes[-1].set_xlabel("time [s]")
    paths.append(_save(fig, f"{name}: CoM position (Fig. 5)", out_dir / f"{name}_fig5_com.png"))

    fig, axes = plt.subplots(3, 2, sharex=True, figsize=(11, 6.5))
    for i in range(3):
        _desired_measured(axes[i, 0], times, np.zeros_like(times), log.l_com[i],
                          f"L_CoM,{'xyz'[i]} [kg·m²/s]")
        _desired_measured(axes[i, 1], times, log.momentum_desired[i], log.momentum[i],
                          f"m v_CoM,{'xyz'[i]} [kg·m/s]")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    paths.append(_save(fig, f"{name}: centroidal momentum (Fig. 6)", out_dir / f"{name}_fig6_momentum.png"))

    paths.append(_phase_portraits(out_dir / f"{name}_fig7_phase.png", name, times, data, mass, com_height,
                                  step_time, step_width))

    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    for ax, i, label in ((axes[0], 1, "L_cy [kg·m²/s]"), (axes[1], 0, "L_cx [kg·m²/s]")):
        _desired_measured(ax, times, log.l_contact_predicted[i], log.l_contact[i], label,
                          desired_label="predicted at step end")
    axes[-1].set_xlabel("time [s]")
    paths.append(_save(fig, f"{name}: contact angular momentum about {{c}} (Fig. 8)",
                       out_dir / f"{name}_fig8_contact_momentum.png"))

    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    for i, ax in enumerate(axes):
        _desired_measured(ax, tracking_times, tracking_wanted[:, i], tracking_measured[:, i],
                          f"v{'xy'[i]} [m/s]", desired_label="command",
                          measured_label="measured, 1 s average")
    axes[-1].set_xlabel("time [s]")
    paths.append(_save(fig, f"{name}: CoM velocity (heading frame, Fig. 9)",
                       out_dir / f"{name}_fig9_velocity.png"))
    return paths


def _desired_measured(ax, times: np.ndarray, desired: np.ndarray, measured: np.ndarray, ylabel: str,
                      desired_label: str = "desired", measured_label: str = "measured") -> None:
    """One axis of the momentum report: desired (dashed red) behind measured (blue)."""
    ax.plot(times, measured, "b-", lw=1.0, label=measured_label)
    ax.plot(times, desired, "r--", lw=1.0, label=desired_label)
    ax.set_ylabel(ylabel, fontsize=8)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=7)


def _phase_portraits(path: Path, name: str, times: np.ndarray, data: np.ndarray, mass: float, height: float,
                     t_step: float, width: float | None) -> Path:
    """Fig. 7: single-support ALIP states, coloured by command, over the ideal orbits (eq. 11-18).

    Samples within SETTLE_S after a command change (or the log's start) are transitions and left
    out, as in the paper; an orbit is drawn for each non-zero command the kept samples were under.
    """
    log = MomentumRecord.unpack(data)
    command = log.command
    changed = np.ones(len(times), dtype=bool)
    changed[1:] = np.any(command[:, 1:] != command[:, :-1], axis=0)
    last_change = np.maximum.accumulate(np.where(changed, times, -np.inf))
    kept = (log.stance != 0) & (times - last_change >= SETTLE_S)
    (p_x, p_y), (l_cx, l_cy) = log.com_in_contact, log.l_contact[:2]
    t = np.linspace(0.0, t_step, 60)

    fig, (sagittal, frontal) = plt.subplots(1, 2, figsize=(11, 4.8))
    sagittal.plot([], [], **_IDEAL_ORBIT, color="0.5", label="ideal orbit (eq. 11-18)")
    for k, (vx, vy) in enumerate(np.unique(command[:, kept].T, axis=0)):
        color = f"C{k % 10}"
        mask = kept & (command[0] == vx) & (command[1] == vy)
        label = f"v = ({vx:g}, {vy:g}) m/s"
        sagittal.plot(p_x[mask], l_cy[mask], ".", ms=2, alpha=0.5, color=color, label=label)
        frontal.plot(p_y[mask], l_cx[mask], ".", ms=2, alpha=0.5, color=color, label=label)
        if vx != 0.0:  # the symmetric orbit from -vT/2 with the momentum of eq. 14
            start = (-0.5 * vx * t_step, alip_general.desired_momentum_y(vx, t_step, mass, height))
            sagittal.plot(*_alip_flow(start, t, mass, height, 1.0), **_IDEAL_ORBIT, color=color)
        if vy != 0.0 and width is not None:
            _frontal_orbits(frontal, vy, t, mass, height, width, **_IDEAL_ORBIT, color=color)
    if width is not None:
        _frontal_orbits(frontal, 0.0, t, mass, height, width, **_IDEAL_ORBIT, color="k",
                        label="ideal in place (vy = 0)")
    sagittal.set_title("sagittal")
    frontal.set_title("frontal" if width is not None else "frontal (no step width: no ideal orbits)")
    for ax, p, ell in ((sagittal, "p_x", "L_cy"), (frontal, "p_y", "L_cx")):
        ax.set_xlabel(f"{p}: CoM rel. contact [m]")
        ax.set_ylabel(f"{ell} [kg·m²/s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, markerscale=4)
    return _save(fig, f"{name}: ALIP states in single support over the ideal orbits (Fig. 7)", path)


def _frontal_orbits(ax, vy: float, t: np.ndarray, mass: float, height: float, width: float, **style) -> None:
    """The lateral orbit of each stance: from the offset the other stance planned (eq. 18) to
    p_start + vy T with L_cx^d (eq. 17) at the end, started where M_y(T)⁻¹ = M_y(−T) puts it."""
    t_step = float(t[-1])
    for planned_in in ("left", "right"):  # the step planned in one stance is walked in the other
        p_start = alip_general.lateral_offset(vy, t_step, width, planned_in)
        end = (p_start + vy * t_step, alip_general.desired_momentum_x(p_start, vy, t_step, mass, height))
        start = _alip_flow(end, np.array([-t_step]), mass, height, -1.0)[:, 0]
        ax.plot(*_alip_flow(start, t, mass, height, -1.0), **style)
        style.pop("label", None)


def _alip_flow(x0, t: np.ndarray, mass: float, height: float, sign: float) -> np.ndarray:
    """(2, len(t)) ALIP states from x0 after t: M_x(t) x0 (eq. 11, sign +1) or M_y(t) x0 (eq. 12, −1)."""
    ell = omega(height, GRAVITY)
    c, s, mhl = np.cosh(ell * t), np.sinh(ell * t), mass * height * ell
    return np.array([c * x0[0] + sign * s / mhl * x0[1], sign * mhl * s * x0[0] + c * x0[1]])


def _save(fig, title: str, path: Path) -> Path:
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_velocity_traces(path: Path, title: str, traces: dict[str, dict]) -> Path:
    """Forward and lateral 1 s averaged velocity of several runs of one command (``traces``: label →
    {"t", "measured" (N, 3), "wanted" (N, 3)}), the command dashed black."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    first = next(iter(traces.values()))
    labels = ("forward velocity [m/s]", "lateral velocity [m/s]")
    for i, (ax, label) in enumerate(zip(axes, labels, strict=True)):
        ax.plot(first["t"], np.array(first["wanted"])[:, i], "k--", lw=1.2, label="command")
        for name, trace in traces.items():
            ax.plot(trace["t"], np.array(trace["measured"])[:, i], lw=1.1, label=name)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return _save(fig, title, path)


def plot_error_bars(path: Path, title: str, metrics: dict[str, dict[str, float]]) -> Path:
    """Grouped bars: per metric (an axis each) one bar per run; an infinite value (a fall) is marked."""
    fig, axes = plt.subplots(1, len(metrics), figsize=(3.2 * len(metrics), 3.4))
    for ax, (metric, values) in zip(np.atleast_1d(axes), metrics.items(), strict=True):
        names = list(values)
        heights = [v if np.isfinite(v) else 0.0 for v in values.values()]
        ax.bar(names, heights, color=[f"C{i}" for i in range(len(names))])
        for i, v in enumerate(values.values()):
            if not np.isfinite(v):
                ax.text(i, 0.0, "fell", ha="center", va="bottom", color="red")
        ax.set_title(metric, fontsize=9)
        ax.tick_params(axis="x", labelsize=8)
        ax.grid(alpha=0.3, axis="y")
    return _save(fig, title, path)


def plot_inertia_prediction(path: Path, title: str, t, true, predicted, labels) -> Path:
    """The six entries of the centroidal inertia over time: the plant's and a prediction's."""
    true, predicted = np.array(true), np.array(predicted)
    fig, axes = plt.subplots(2, 3, sharex=True, figsize=(11, 5))
    for k, ax in enumerate(axes.flat):
        ax.plot(t, true[:, k], "k", lw=1.2, label="plant")
        ax.plot(t, predicted[:, k], "r--", lw=1.1, label="CCINN")
        ax.set_title(f"{labels[k]} [kg·m²]", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    return _save(fig, title, path)
