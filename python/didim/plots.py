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


