"""Figures an engineer looks at: measured against simulated force with the error (Fig. 6), parameter trajectories
over the iterations (Fig. 5)."""

from __future__ import annotations

from .model import Model
from .recording import Recording
from .result import IdentificationResult
from .simulation import simulate


def full_params(result: IdentificationResult) -> dict:
    """The identified parameters together with the frozen ones, ready for :func:`didim.simulate`."""
    return {**result.frozen, **result.params}


def plot_fit(recording: Recording, result: IdentificationResult, *, title: str = ""):
    """Two panels: measured and simulated motor force with their difference (cross-test view of Fig. 6), and the
    parameters over the iterations normalised by their final values (Fig. 5)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    if result.structure is None and result.options.get("frozen_structure"):  # step 2: its flexible parameter set
        structure = Model.from_dict(result.options["frozen_structure"])
        model = structure.kind
        sim = simulate(recording, dict(result.frozen), structure)
    else:  # the result's own structure (terms, delay, force lag, friction law) and numerics
        model = result.model
        sim = simulate(recording, result)
    fig, axes = plt.subplots(2, 1, figsize=(11, 7), gridspec_kw=dict(height_ratios=[3, 2]))
    sim.plot(recording, ax=axes[0])
    axes[0].set_title(title or f"{recording.name}: {result.method}, {model} model — measured (red), simulated (blue), "
                      f"error (black): {100 * sim.relative_error(recording):.2f} %")
    result.plot_history(ax=axes[1])
    fig.tight_layout()
    return fig


__all__ = ["plot_fit", "full_params"]


def plot_robot_forces(recording, force_sim, *, title: str = ""):
    """One panel per joint: the measured and the simulated force (torque) of a robot's record and their difference,
    with each joint's relative error in its title."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    import numpy as np

    n = recording.ndof
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.9 * n + 0.6), sharex=True, squeeze=False)
    t = recording.t
    for j, ax in enumerate(axes[:, 0]):
        y, ys = recording.force[:, j], force_sim[:, j]
        err = np.linalg.norm(y - ys) / np.linalg.norm(y)
        unit = "N·m" if recording.joint_kinds[j] == "revolute" else "N"
        # one axis's colours; the simulated line thinner and under the measured one, so that both stay visible
        ax.plot(t, ys, lw=1.2, color="tab:blue", alpha=0.7, label="simulated", zorder=2)
        ax.plot(t, y, lw=0.5, color="tab:red", label="measured", zorder=3)
        ax.plot(t, y - ys, lw=0.6, color="0.4", label="difference", zorder=1)
        ax.set_ylabel(f"{recording.joint_names[j]}\n({unit})", fontsize=8)
        ax.set_title(f"{recording.joint_names[j]}: {100 * err:.2f} %", fontsize=8, loc="right")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=3, loc="upper left")
    axes[-1, 0].set_xlabel("time (s)")
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    return fig
