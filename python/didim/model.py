"""The model structure as one object: what a result was identified with and what the simulator needs to reproduce it.

A :class:`Model` is the kind (rigid or flexible), the constant force offset, the extra terms, the actuation delay, the
backlash of the coupling and the Coulomb smoothing. Every identification result carries one (``result.structure``),
with all its parameters (``result.all_params``, frozen ones included), so ``didim.simulate(rec, result)`` reproduces
the result's own closed loop, and a saved result reloads with it (:func:`load_result`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, Optional, Tuple


from . import _checks, _core
from ._errors import DataError
from .simulation import COULOMB_LAWS, MODELS, Term, param_names

@dataclass(frozen=True)
class Model:
    """A model structure. ``kind``: "rigid" (eq. (6), M, Fv, Fc) or "flexible" (eq. (2), M1, Fv1, Fc1, M2, Fv2, Fc2,
    K12); ``offset``: a constant force OF (N); ``terms``: extra :class:`didim.Term` s (each on the motor or the load);
    ``force_lag``: time constant (s) of a first-order lag from the command to the applied force; ``delay``: actuation delay in
    samples; ``backlash_gap``: total width (m) of a dead zone in K12 (flexible only); ``coulomb_eps``: velocity scale
    (m/s or rad/s) of the smoothed Coulomb sign, 0 for the hard sign, None for the record's
    (:func:`didim.simulation.default_coulomb_eps`; an identified model carries the number it was fitted with)."""

    kind: str = "rigid"
    offset: bool = False
    terms: Tuple[Term, ...] = field(default_factory=tuple)
    delay: int = 0
    backlash_gap: Optional[float] = None
    force_lag: float = 0.0
    coulomb_eps: Optional[float] = None
    coulomb_law: str = "algebraic"

    def __post_init__(self):
        if self.kind not in MODELS:
            raise DataError(f"unknown model kind {self.kind!r}: use one of {', '.join(MODELS)}")
        if not isinstance(self.kind, str) or not isinstance(self.terms, (tuple, list)):
            raise DataError(f"a model needs a kind (text) and a list of terms, got {self.kind!r}, {self.terms!r}")
        for t in self.terms:
            if not isinstance(t, (Term, tuple, list)) or (not isinstance(t, Term) and len(t) not in (2, 3, 4, 5)):
                raise DataError(f"a model term is a didim.Term or a (name, kind, hyper[, dof[, width]]) tuple, got {t!r}")
        object.__setattr__(self, "terms", tuple(t if isinstance(t, Term) else Term(*t) for t in self.terms))
        if self.backlash_gap is not None:
            object.__setattr__(self, "backlash_gap", _checks.real("backlash_gap", self.backlash_gap, "m", lo=0.0))
        object.__setattr__(self, "delay", _checks.whole("delay", self.delay, hint=" (samples)"))
        object.__setattr__(self, "force_lag", _checks.real("force_lag", self.force_lag, "s", lo=0.0, lo_open=False))
        _checks.one_of("coulomb_law", self.coulomb_law, COULOMB_LAWS)
        if self.coulomb_eps is not None:
            object.__setattr__(self, "coulomb_eps", _checks.real("coulomb_eps", self.coulomb_eps, "m/s", lo=0.0,
                                                                 lo_open=False))

    def describe(self) -> str:
        """In words: the kind and every structure field that is not the default."""
        parts = [f"{self.kind} model"]
        if self.offset:
            parts.append("an offset OF")
        if self.terms:
            parts.append("terms " + ", ".join(f"{t.name} ({t.kind})" for t in self.terms))
        if self.delay:
            parts.append(f"a delay of {self.delay} sample{'s' if self.delay != 1 else ''}")
        if self.force_lag:
            parts.append(f"a force lag of {1e3 * self.force_lag:.3g} ms")
        if self.backlash_gap is not None:
            parts.append(f"a backlash gap of {self.backlash_gap:g} m")
        if self.coulomb_eps is not None:
            parts.append(f"coulomb_eps {self.coulomb_eps:g}")
        if self.coulomb_law != "algebraic":
            parts.append(f"a {self.coulomb_law} Coulomb law")
        return parts[0] + (" with " + "; ".join(parts[1:]) if len(parts) > 1 else "")

    def param_names(self) -> list:
        """Parameter names in the order of the parameter vector."""
        return param_names(self.kind, self.offset, self.terms)

    def units(self) -> Dict[str, str]:
        """Unit of each parameter (SI, load side), as the core's basis functions give them."""
        specs = [t.spec() for t in self.terms] or None
        return dict(zip(self.param_names(), _core.param_units(self.kind, self.offset, specs, self.backlash_gap)))

    def sim_kw(self) -> Dict[str, Any]:
        """Keyword arguments of :func:`didim.simulate` that describe this structure."""
        return dict(offset=self.offset, terms=self.terms, delay=self.delay, force_lag=self.force_lag,
                    backlash_gap=self.backlash_gap,
                    coulomb_eps=self.coulomb_eps, coulomb_law=self.coulomb_law)

    def to_dict(self) -> Dict[str, Any]:
        return {"kind": self.kind, "offset": self.offset, "terms": [list(t.spec()) for t in self.terms],
                "delay": self.delay, "force_lag": self.force_lag, "backlash_gap": self.backlash_gap,
                "coulomb_eps": self.coulomb_eps, "coulomb_law": self.coulomb_law}

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "Model":
        if not isinstance(d, dict):
            raise DataError(f"a model structure must be a JSON object, got {type(d).__name__}")
        unknown = set(d) - {"kind", "offset", "terms", "delay", "force_lag", "backlash_gap", "coulomb_eps",
                             "coulomb_law"}
        if unknown:
            raise DataError(f"unknown model field(s) {', '.join(sorted(unknown))}")
        raw = d.get("terms") or []
        if not isinstance(raw, list) or not all(isinstance(t, list) and len(t) in (3, 4, 5) for t in raw):
            raise DataError("model terms must be a list of [name, kind, hyper, dof, width] lists (dof 'motor' and "
                            "width 0 by default)")
        terms = tuple(Term(*t) for t in raw)
        offset = d.get("offset", False)
        if not isinstance(offset, bool):
            raise DataError(f"model field offset must be true or false, got {offset!r}")
        return cls(kind=d.get("kind", "rigid"), offset=offset, terms=terms, delay=d.get("delay", 0),
                   force_lag=d.get("force_lag", 0.0),
                   backlash_gap=d.get("backlash_gap"), coulomb_eps=d.get("coulomb_eps"),
                   coulomb_law=d.get("coulomb_law", "algebraic"))

    @classmethod
    def of_result(cls, kind: str, params: Dict[str, float], options: Dict[str, Any]) -> Optional["Model"]:
        """The structure a method's options describe, or None for results that are not parameter sets of a model
        (step 2's λ, f_n_flex)."""
        if kind not in MODELS:
            return None
        terms = tuple(Term(*t) for t in options.get("terms") or ())
        m = cls(kind=kind, offset="OF" in params, terms=terms, delay=int(options.get("delay") or 0),
                force_lag=float(options.get("force_lag") or 0.0),
                backlash_gap=options.get("backlash_gap"),
                coulomb_eps=options.get("coulomb_eps"),
                coulomb_law=options.get("coulomb_law", "algebraic"))
        return m if set(m.param_names()) >= set(params) else None


def load_result(path) -> "IdentificationResult":  # noqa: F821
    """Reloads a result saved as JSON (``result.save("r.json")``, ``didim identify --json``) with its model structure,
    so that ``didim.simulate(rec, load_result("r.json"))`` applies it to another record (the paper's cross-test)."""
    from .result import IdentificationResult

    from ._io import check_input

    path = check_input(path, "result file (JSON)")
    try:
        with open(path, "r", encoding="utf-8") as f:
            text = f.read(64 * 1024 * 1024)
    except (OSError, ValueError) as e:
        raise DataError(f"cannot read the result {path!r}: {e}") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as e:
        raise DataError(f"{os.fspath(path)}: not a JSON result ({e})") from None
    except RecursionError:
        raise DataError(f"{os.fspath(path)}: not a didim result (its JSON is nested too deeply)") from None
    if not isinstance(d, dict) or "params" not in d or "model" not in d:
        raise DataError(f"{os.fspath(path)}: not a didim result (needs 'model' and 'params'; save one with "
                        "result.save('r.json') or didim identify --json)")
    try:
        return IdentificationResult.from_dict(d)
    except DataError as e:
        raise DataError(f"{os.fspath(path)}: {e}") from None
    except RecursionError:
        raise DataError(f"{os.fspath(path)}: not a didim result (its steps are nested too deeply)") from None


__all__ = ["Model", "load_result"]
