"""A record's start and lead-in in the doctor's words (the summary and the HTML report share them)."""

from __future__ import annotations

from typing import Any, Dict

from .effects import _g


def start_words(s: Dict[str, Any]) -> str:
    """A record's start (the doctor's ``locate["start"]``) in words."""
    where = ("(after its lead-in: the simulation does not join the log at once)" if s.get("lead_in") else
             "(at rest on the reference: the closed loop was already running when the log began)")
    return (f"{s['record']} begins with the axis {_g(1e6 * s['initial_gap_m'])} µm from where the simulation is "
            f"{where}; its first {_g(1e3 * s['seconds'])} ms hold {100 * s['residual_share']:.0f} % of its residual "
            f"energy, which comes from that start, not from the model; after them the force error is "
            f"{100 * s['force_error_after_start']:.2f} %")


def lead_in_words(s: Dict[str, Any]) -> str:
    """A record's lead-in (the doctor's ``locate["lead_in"]``) in words."""
    how = ("reconstructed back to the rest it left (to start at the first sample instead: lead_in=None, on the command "
           "line --lead-in none)" if s["reconstructed"] else "given with the record")
    return (f"{s['record']} begins in motion (its reference at {_g(1e3 * s['speed_m_s'])} mm/s, at "
            f"{_g(1e3 * s['first_m'])} mm): the simulation starts {_g(1e3 * s['seconds'])} ms earlier, at rest at "
            f"{round(1e3 * s['rest_m'], 3) + 0.0:.3f} mm, on the reference {how}")
