"""A finding of the doctor (one axis's or a robot joint's) and the practical significance it must reach on held-out
data: what :mod:`didim.doctor` and :mod:`didim.doctor.robot` both report."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, Optional

from ..formats._io import jsonable as _clean

#: Practical significance: an accepted effect must lower the held-out closed-loop force error by at least this share
#: of it (besides being statistically significant). Real friction differs from any smooth law, and at low noise a test
#: finds such differences; an engineer cares about an effect that changes the fit, not about one that is detectable.
MIN_HELDOUT_GAIN = 0.05

#: The loss whose held-out difference the one-sided Diebold-Mariano test judges (both doctors): the absolute errors.
#: A closed loop's force errors are heavy-tailed (large at a few starts, stops and reversals), and their squares let
#: those few samples set the test's variance: on a belt axis whose force lags 0.4 ms, the model with the lag lowered
#: the held-out mean square by 62 % (error 1.65 → 1.02 %) at p = 0.11 on the squares, p = 0.0009 on the absolute
#: errors; a base that swings far off at moments is the same case. The practical threshold stays on the RMS error.
HELDOUT_LOSS = "absolute"

#: Two candidates are ambiguous when one's regressor spans more than this share of the other's (beyond the model's
#: own columns): the record cannot say which it is. A candidate the model's own columns span by as much cannot be
#: seen at all (the robot doctor's blind spots). Both doctors.
AMBIGUOUS_SHARE = 0.9


@dataclass
class Finding:
    """One effect the doctor found: its name (see ``EFFECTS``), estimated parameters with σ, the evidence (test
    statistic, p-values, share of the residual it explains), the fit before and after on training and validation
    data (relative force errors), and a sentence of physics."""

    effect: str
    params: Dict[str, float]
    std: Dict[str, float]
    statistic: Dict[str, float]
    evidence: str
    physics: str
    fit: Dict[str, float] = field(default_factory=dict)
    where: Dict[str, Any] = field(default_factory=dict)
    accepted: bool = True
    words: str = ""  # the fitted effect in an engineer's words, with units
    note: str = ""  # for a candidate not confirmed: what the held-out residual shows of it
    joint: Optional[str] = None  # a robot's joint it acts on (None: one axis, or every joint of a robot)

    def to_dict(self) -> Dict[str, Any]:
        return _clean({
            "effect": self.effect, "joint": self.joint, "params": self.params, "std": self.std,
            "statistic": self.statistic,
            "evidence": self.evidence, "physics": self.physics, "fit": self.fit, "where": self.where,
            "words": self.words, "note": self.note,
        })

    def held_out(self) -> str:
        f = self.fit
        if "valid_force_before" in f and "valid_force_after" in f:
            return f"held-out force error {100 * f['valid_force_before']:.2f} % -> {100 * f['valid_force_after']:.2f} %"
        if "valid_before" in f and "valid_after" in f:
            return (f"held-out force error (decimated) {100 * f['valid_before']:.2f} % -> "
                    f"{100 * f['valid_after']:.2f} %")
        return ""
