"""PNG figures of template walks: stride velocity against the command, and phase portraits."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


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


def _save(fig, title: str, path: Path) -> Path:
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
