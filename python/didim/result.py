"""Results of an identification: parameters with their uncertainty, the work done, and the history."""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Tuple

import numpy as np

from . import _checks
from ._errors import DataError
from .formats._io import check_input, jsonable
from .model import Model

#: Units of the paper's parameters (SI, load side) and of step 2's mode parameters; a result with a model structure
#: takes its units from the model's basis functions (:attr:`IdentificationResult.units`).
UNITS = {
    "M": "kg",
    "Fv": "N/(m/s)",
    "Fc": "N",
    "OF": "N",
    "M1": "kg",
    "Fv1": "N/(m/s)",
    "Fc1": "N",
    "M2": "kg",
    "Fv2": "N/(m/s)",
    "Fc2": "N",
    "K12": "N/m",
    "lambda": "-",
    "f_n_flex": "Hz",
    "load_share": "-",
}


@dataclass
class Iteration:
    """One iteration: the parameters it produced, their %σ, the regression's relative error ‖Y − Wχ‖/‖Y‖ and the
    relative output error ‖Y − Y_s‖/‖Y‖ of the simulation that built W (NaN where not defined)."""

    k: int
    params: Dict[str, float]
    rel_std_pct: Dict[str, float]
    relative_error: float
    output_error: float


@dataclass
class IdentificationResult:
    """Identified parameters (SI, load side) with σ and %σ (eq. (15)), the final relative error, the work done and the
    per-iteration history. ``converged`` is False with a ``message`` when the method stopped without converging or
    detected divergence."""

    model: str
    method: str
    params: Dict[str, float]
    std: Dict[str, float]
    rel_std_pct: Dict[str, float]
    relative_error: float
    iterations: int
    simulations: int
    elapsed_s: float
    converged: bool = True
    message: str = ""
    initial: Dict[str, float] = field(default_factory=dict)
    output_error: float = float("nan")
    history: List[Iteration] = field(default_factory=list)
    frozen: Dict[str, float] = field(default_factory=dict)
    options: Dict[str, Any] = field(default_factory=dict)
    covariance: Optional[np.ndarray] = None
    steps: Dict[str, "IdentificationResult"] = field(default_factory=dict)
    #: What the method did beyond the plain iteration (variant chosen, steps shortened, ...), in plain words.
    notes: List[str] = field(default_factory=list)
    #: The model structure the parameters belong to (:class:`didim.Model`); derived from the method's options.
    structure: Optional[Any] = None
    #: Closed-loop simulated force error on all samples, ‖τ − τ_sim‖/‖τ‖ (the headline measure; NaN until computed).
    force_error: float = float("nan")
    #: For a record that began away from the simulation's start (at rest on the reference): how long (s) the
    #: simulation takes to join it, and the force error after that (0 and NaN for a record that starts there).
    start_s: float = 0.0
    force_error_after_start: float = float("nan")
    #: The closed-loop force error below ``options["band_hz"]``, the band the method fitted in (measured and
    #: simulated force low-passed alike, zero-phase): on a coarse encoder the full-rate error is mostly encoder-count
    #: chatter the velocity loop amplifies, which no model reproduces sample by sample (NaN when not computed).
    force_error_band: float = float("nan")
    #: "linear" (m, N, kg) or "rotary" (rad, N·m, kg·m²): the axis of the record the result was identified on; the
    #: numbers are SI either way, and :attr:`units` names them for this axis.
    axis: str = "linear"
    #: A robot's result (its :attr:`structure` a model of a :class:`didim.Robot`): the base map
    #: (:class:`didim.robots.BaseParameters`: what each base parameter combines) and each joint's closed-loop force
    #: error; ``options["controller_check"]`` holds each joint's controller check. :mod:`didim.methods.robot`
    #: reads and writes them.
    base: Optional[Any] = None
    force_error_per_joint: Dict[str, float] = field(default_factory=dict)

    def __post_init__(self):
        if self.structure is None:
            self.structure = Model.of_result(self.model, self.all_params, self.options)

    @property
    def robot(self):
        """The robot (:class:`didim.Robot`, its URDF) a robot's parameters belong to: its model's; None for one axis."""
        return None if self.structure is None else self.structure.robot

    @property
    def law(self) -> Optional[Tuple[str, Tuple[float, ...]]]:
        """A robot's friction law through zero speed (shape, each joint's ε in rad/s or m/s): its model's."""
        return None if self.structure is None else self.structure.law

    @property
    def offset(self) -> bool:
        """Whether the model has a constant force (torque) per joint."""
        return bool(self.structure is not None and self.structure.offset)

    @property
    def units(self) -> Dict[str, str]:
        """The SI unit of each parameter (from the model's basis functions where the result has a structure), for the
        result's axis (kg·m², N·m·s/rad, N·m on a rotary one)."""
        from .units import label

        if self.robot is not None:  # each joint's own units; a base parameter's its first standard parameter's
            known = self.structure.units()
            kinds = dict(zip(self.robot.joint_names, self.robot.joint_kinds))

            def unit(k: str) -> str:
                first = k if k in known else k.split(" ")[0]  # a base parameter: its first standard parameter's
                joint = self.structure.joint_of(first)
                if joint is None:
                    return known.get(first, "")
                return label(known.get(first, ""), "linear" if kinds[joint] == "prismatic" else "rotary")

            return {k: unit(k) for k in (*self.params, *self.frozen)}
        known = self.structure.units() if self.structure is not None else {}
        return {k: label(known.get(k, UNITS.get(k, "")), self.axis) for k in (*self.params, *self.frozen)}

    def set_axis(self, axis: str) -> None:
        """Names this result's units (and its steps') for a ``"linear"`` or ``"rotary"`` axis."""
        self.axis = axis
        for s in self.steps.values():
            s.set_axis(axis)

    @property
    def all_params(self) -> Dict[str, float]:
        """Every parameter of the model, the frozen ones included, in the order of the parameter vector."""
        full = {**self.frozen, **self.params}
        if self.structure is not None and self.robot is None:
            return {n: full[n] for n in self.structure.param_names() if n in full}
        return full

    @property
    def names(self) -> List[str]:
        return list(self.params)

    def to_dict(self) -> Dict[str, Any]:
        """A JSON-ready dict with the contract keys: model, method, params, std, rel_std_pct, relative_error, iterations,
        simulations, elapsed_s (plus converged, message, initial, output_error, frozen, options, history); a robot's
        adds ``"kind": "robot"``, its robot (URDF), base map, friction law and each joint's force error."""
        if self.robot is not None:
            return _robot_dict(self)
        d = {
            "model": self.model,
            "method": self.method,
            "params": self.params,
            "std": self.std,
            "rel_std_pct": self.rel_std_pct,
            "relative_error": self.relative_error,
            "output_error": self.output_error,
            "iterations": self.iterations,
            "simulations": self.simulations,
            "elapsed_s": self.elapsed_s,
            "converged": self.converged,
            "message": self.message,
            "initial": self.initial,
            "frozen": self.frozen,
            "options": {k: v for k, v in self.options.items() if not k.startswith("_")},
            "history": [asdict(h) for h in self.history],
            "steps": {k: v.to_dict() for k, v in self.steps.items()},
            "notes": list(self.notes),
            "units": self.units,
            "structure": self.structure.to_dict() if self.structure is not None else None,
            "force_error": self.force_error,
            "start_s": self.start_s,
            "force_error_after_start": self.force_error_after_start,
            "axis": self.axis,
            "force_error_band": self.force_error_band,
        }
        return jsonable(d)

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "IdentificationResult":
        """The inverse of :meth:`to_dict` (history and steps included)."""

        def floats(x, what):
            if x is None:
                return {}
            if not isinstance(x, dict):
                raise DataError(f"result field {what!r} must be an object name -> value, got {type(x).__name__}")
            out = {}
            for k, v in x.items():
                if v is None:
                    out[str(k)] = float("nan")
                elif isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise DataError(f"result field {what!r}: {k} must be a number, got {v!r}")
                else:
                    out[str(k)] = float(v)
            return out

        def num(x, what, default=float("nan")):
            if x is None:
                return default
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                raise DataError(f"result field {what!r} must be a number, got {x!r}")
            return float(x)

        def count(x, what):
            return 0 if x is None else _checks.whole(f"result field {what!r}", x, lo=0)

        def typed(x, kind, what, default):
            if x is None:
                return default
            if not isinstance(x, kind):
                raise DataError(f"result field {what!r} must be {'an object' if kind is dict else 'a ' + kind.__name__}"
                                f", got {type(x).__name__}")
            return x

        if isinstance(d, dict) and d.get("kind") == "robot":  # a robot's result carries its robot
            try:
                return _robot_from_dict(d)
            except DataError as e:
                raise DataError(f"not a readable robot result: {e}") from None
            except (KeyError, TypeError, ValueError) as e:
                raise DataError(f"not a readable robot result ({type(e).__name__}: {e})") from None
        if not isinstance(d, dict) or "params" not in d or "model" not in d:
            raise DataError("a result is an object with 'model' and 'params' (save one with result.save('r.json') or "
                            "didim identify --json)")
        history = []
        for i, h in enumerate(typed(d.get("history"), list, "history", [])):
            h = typed(h, dict, f"history[{i}]", {})
            history.append(Iteration(k=count(h.get("k", i + 1), f"history[{i}].k"),
                                     params=floats(h.get("params"), f"history[{i}].params"),
                                     rel_std_pct=floats(h.get("rel_std_pct"), f"history[{i}].rel_std_pct"),
                                     relative_error=num(h.get("relative_error"), f"history[{i}].relative_error"),
                                     output_error=num(h.get("output_error"), f"history[{i}].output_error")))
        structure = Model.from_dict(d["structure"]) if d.get("structure") else None
        params = floats(d["params"], "params")
        frozen = floats(d.get("frozen"), "frozen")
        model = typed(d["model"], str, "model", "")
        if structure is not None:
            known = structure.param_names()
            unknown = [k for k in list(params) + list(frozen) if k not in known]
            if unknown:
                raise DataError(f"result parameter(s) {', '.join(unknown)} are not parameters of its model "
                                f"({', '.join(known)})")
        notes = typed(d.get("notes"), list, "notes", [])
        if not all(isinstance(n, str) for n in notes):
            raise DataError("result field 'notes' must be a list of texts")
        steps = typed(d.get("steps"), dict, "steps", {})
        r = cls(model=model, method=typed(d.get("method"), str, "method", ""), params=params,
                std=floats(d.get("std"), "std"), rel_std_pct=floats(d.get("rel_std_pct"), "rel_std_pct"),
                relative_error=num(d.get("relative_error"), "relative_error"),
                iterations=count(d.get("iterations"), "iterations"),
                simulations=count(d.get("simulations"), "simulations"),
                elapsed_s=num(d.get("elapsed_s"), "elapsed_s", 0.0),
                converged=typed(d.get("converged"), bool, "converged", True),
                message=typed(d.get("message"), str, "message", ""),
                initial=floats(d.get("initial"), "initial"), output_error=num(d.get("output_error"), "output_error"),
                history=history, frozen=frozen, options=dict(typed(d.get("options"), dict, "options", {})),
                steps={str(k): cls.from_dict(v) for k, v in steps.items()},
                notes=notes, structure=structure, force_error=num(d.get("force_error"), "force_error"),
                start_s=num(d.get("start_s"), "start_s", 0.0),
                force_error_after_start=num(d.get("force_error_after_start"), "force_error_after_start"),
                axis=typed(d.get("axis"), str, "axis", "linear"),
                force_error_band=num(d.get("force_error_band"), "force_error_band"))
        if r.axis not in ("linear", "rotary"):
            raise DataError(f"result field 'axis' must be 'linear' or 'rotary', got {r.axis!r}")
        return r

    def to_json(self, **kw) -> str:
        return json.dumps(self.to_dict(), indent=2, **kw)

    def save(self, path) -> None:
        """Writes the result to ``path``: JSON for ``.json`` (the contract of :meth:`to_dict`), the summary table for
        ``.txt``. Atomic: a failed write leaves the old file as it was."""
        from .formats._io import write_text

        ext = os.path.splitext(os.fspath(path))[1].lower()
        if ext == ".json":
            write_text(path, self.to_json() + "\n")
        elif ext == ".txt":
            write_text(path, self.summary() + "\n")
        else:
            raise DataError(f"cannot save a result as {ext or 'a file without extension'!r}: use .json or .txt")

    def summary(self) -> str:
        """A table in the paper's layout: χ⁰, χ̂ᵏ and %σ per parameter, then ‖Y − Wχ‖/‖Y‖ (a robot's: each joint's
        force error, its friction law, the parameters with their %σ)."""
        if self.robot is not None:
            return _robot_summary(self)
        k = self.iterations
        head = f"{self.method} identification of the {self.model} model"
        lines = [head, "=" * len(head)]
        est = f"χ{k}" if k > 0 else "χ̂"  # the paper's χᵏ after k iterations (none: a result not iterated)
        lines.append(f"{'parameter':<18}{'χ0':>12}{est:>14}{'σ':>12}{'%σ':>9}")
        for name, v in self.params.items():
            unit = self.units.get(name, "")
            label = f"{name} ({unit})" if unit else name
            x0 = self.initial.get(name, float("nan"))
            lines.append(
                f"{label:<18}{_fmt(x0):>12}{_fmt(v):>14}{_fmt(self.std.get(name, float('nan'))):>12}"
                f" {_pct(self.rel_std_pct.get(name, float('nan'))):>8}"
            )
        for name, v in self.frozen.items():
            lines.append(f"{name + ' (frozen)':<18}{'':>12}{_fmt(v):>14}{'-':>12}{'-':>9}")
        if math.isfinite(self.force_error):
            lines.append(f"closed-loop force error (simulated vs measured, all samples) = {100 * self.force_error:.2f} %"
                         + (f"; {100 * self.force_error_after_start:.2f} % after the first {1e3 * self.start_s:.0f} ms, "
                            "where the simulation joins a record that began elsewhere than its start" if self.start_s > 0 and math.isfinite(self.force_error_after_start) else "")
                         + (f"; below {self.options['band_hz']:g} Hz, the band the fit used: "
                            f"{100 * self.force_error_band:.2f} %"
                            + (" (the rest is mostly encoder-count chatter above that band, which no model follows "
                               "sample by sample)" if self.force_error > 2 * self.force_error_band else "")
                            if math.isfinite(self.force_error_band) and self.options.get("band_hz") else ""))
        chk = self.options.get("controller_check")
        if isinstance(chk, dict) and "mismatch" in chk:
            lines.append(f"controller check: its law on the logged qr and qm gives the logged force within "
                         f"{100 * chk['mismatch']:.3g} %" + ("" if chk.get("passed") else " (NOT within the "
                                                          f"{100 * chk['tolerance']:g} % accepted: {chk.get('likely')})"))
        if math.isfinite(self.relative_error) and not self.method.startswith("oe-"):  # OE methods fit no regression
            lines.append(f"regression error ‖Y − Wχ‖/‖Y‖ (decimated) = {100 * self.relative_error:.2f} %")
        if math.isfinite(self.output_error):
            lines.append(f"decimated output error ‖Y − Ys‖/‖Y‖ = {100 * self.output_error:.2f} %")
        lines.append(f"{k} iteration{'' if k == 1 else 's'}, {self.simulations} simulation"
                     f"{'' if self.simulations == 1 else 's'}, {self.elapsed_s:.3f} s")
        if not self.converged:
            lines.append(f"NOT CONVERGED: {self.message}")
        elif self.message:
            lines.append(self.message)
        lines.extend(f"note: {n}" for n in self.notes)
        return "\n".join(l for l in lines if l != "")

    def __str__(self) -> str:
        return self.summary()

    def plot_history(self, ax=None):
        """Parameter trajectories over the iterations, normalised by their final value (like Fig. 5)."""
        import matplotlib.pyplot as plt

        if ax is None:
            fig, ax = plt.subplots(figsize=(7, 4))
        else:
            fig = ax.figure
        if not self.history:
            ax.text(0.5, 0.5, "no history", ha="center", transform=ax.transAxes)
            return fig
        ks = [h.k for h in self.history]
        for name in self.params:
            vals = np.array([h.params.get(name, np.nan) for h in self.history])
            final = self.params[name]
            ax.plot(ks, vals / final if final else vals, marker="o", label=name)
        ax.set_xlabel("iteration k")
        ax.set_ylabel("χᵏ / χ̂ (final)")
        ax.set_title(f"{self.method}, {self.model} model")
        ax.grid(True, alpha=0.3)
        ax.legend(ncol=2, fontsize=8)
        return fig


def iterations_of(errors) -> List[Iteration]:
    """DIDIM's closed-loop force error at each iteration, as a result's history."""
    return [Iteration(k=i, params={}, rel_std_pct={}, relative_error=math.nan, output_error=float(e))
            for i, e in enumerate(errors)]


#: What an elastic robot result keeps of its steps in its options (saved with it).
ELASTIC_OPTIONS = ("modes", "rigid_force_error", "rigid_force_error_per_joint")


def _robot_dict(res: IdentificationResult) -> Dict[str, Any]:
    """A robot result as JSON (``"kind": "robot"``, read back by :func:`_robot_from_dict`)."""

    return jsonable({"kind": "robot", "method": res.method, "params": res.params, "std": res.std,
                     "std_pct": res.rel_std_pct, "offset": res.offset, "force_error": res.force_error,
                     "start_s": res.start_s, "force_error_after_start": res.force_error_after_start,
                     "force_error_per_joint": res.force_error_per_joint, "converged": res.converged,
                     "iterations": res.iterations, "message": res.message, "elapsed_s": res.elapsed_s,
                     "notes": res.notes, "history": [h.output_error for h in res.history],
                     "frozen": res.frozen,
                     "controller_check": res.options.get("controller_check"),
                     # an elastic result's modes and its rigid step's errors (a start for step 3: didim_elastic)
                     "elastic_steps": {k: res.options[k] for k in ELASTIC_OPTIONS if k in res.options},
                     "friction_law": None if res.law is None else {"shape": res.law[0], "eps": list(res.law[1])},
                     "robot": {"name": res.robot.name, "joints": res.robot.joint_names, "urdf": res.robot.urdf},
                     "elastic": list(res.structure.elastic),
                     "terms": [t.to_dict() for t in res.structure.terms],
                     "load_friction": list(res.structure.load_friction),
                     # each elastic joint's dead zone between rotor and link (total width, rad or m; 0 for none)
                     "backlash_gap": (list(res.structure.backlash_gap) if res.structure.backlash_gap is not None
                                      else None),
                     "base": {"names": list(res.base.names), "standard_names": list(res.base.standard_names),
                              "K": res.base.K.tolist(), "independent": list(res.base.independent)}})


def _robot_summary(res: IdentificationResult) -> str:
    """A robot result in words: the method and its work, each joint's force error, the friction law, the parameters
    with their %σ, the notes."""
    lines = [f"{res.method} on a {res.robot.ndof}-joint robot ({res.robot.name}): "
             + ("converged" if res.converged else "NOT converged") + f" in {res.iterations} iteration(s), "
             f"{res.elapsed_s:.1f} s; "
             + (f"closed-loop force error {100 * res.force_error:.2f} % (all joints together; per joint below)"
                if math.isfinite(res.force_error) else
                "its closed loop could not be simulated (no closed-loop force error: see the notes)")
             + (f" ({100 * res.force_error_after_start:.2f} % after the first {1e3 * res.start_s:.0f} ms, where the "
                "simulation joins a record that began in motion)" if res.start_s > 0 else "")]
    lines += [f"  {j}: force error {100 * e:.2f} %" for j, e in res.force_error_per_joint.items()]
    if res.law is not None:
        eps = ", ".join(f"{j} {e:.4g} {'m/s' if k == 'prismatic' else 'rad/s'}"
                        for j, k, e in zip(res.robot.joint_names, res.robot.joint_kinds, res.law[1]))
        lines.append(f"  friction law through zero speed: {res.law[0]}, smoothing speed ε: {eps}")
    if res.structure is not None and res.structure.backlash_gap is not None:
        lines.append("  backlash (dead zone between rotor and link, total width): " + ", ".join(
            f"{j} {g:.4g} {'m' if k == 'prismatic' else 'rad'}"
            for j, k, g in zip(res.robot.joint_names, res.robot.joint_kinds, res.structure.gaps) if g > 0))
    units = res.units
    for k, v in res.params.items():
        unit = f" {units[k]}" if units.get(k) else ""
        lines.append(f"  {k} = {v:.6g}{unit} (±{res.rel_std_pct.get(k, math.nan):.2g} %)")
    lines += [f"note: {x}" for x in res.notes]
    return "\n".join(lines)


def robot_result(method: str, params: Dict[str, float], std: Dict[str, float], model: Model, base,
                 **kw) -> IdentificationResult:
    """A robot's :class:`didim.IdentificationResult` (every plant's result type) of its ``model`` (a
    :class:`didim.Model` of a robot, with the friction law it was fitted with)."""
    pct = {k: 100 * std[k] / abs(v) if v else math.inf for k, v in params.items() if k in std}
    fields = dict(relative_error=math.nan, iterations=0, simulations=0, elapsed_s=0.0)
    fields.update(kw)
    return IdentificationResult(model="robot", method=method, params=params, std=std, rel_std_pct=pct,
                                structure=model, base=base, **fields)


def _field(d: Dict[str, Any], path: str) -> Any:
    """A saved robot result's field ``path`` ("robot.urdf"), or a DataError naming it when it is missing."""
    x: Any = d
    for key in path.split("."):
        if not isinstance(x, dict) or key not in x:
            raise DataError(f"its field {path!r} is missing (removed or renamed by hand?): save the result again")
        x = x[key]
    return x


def _robot_from_dict(d: Dict[str, Any]) -> IdentificationResult:
    from .robots.chain import BaseParameters, Robot

    robot = Robot.from_urdf_string(_field(d, "robot.urdf"), _field(d, "robot.joints"))
    try:
        k = np.array(_field(d, "base.K"), dtype=float)
    except (TypeError, ValueError):
        raise DataError("its field 'base.K' is not a table of numbers (one row of equal length per base parameter): "
                        "save the result again") from None
    base = BaseParameters(tuple(_field(d, "base.standard_names")), tuple(_field(d, "base.names")), k,
                          tuple(_field(d, "base.independent")))
    _check_robot_parts(d, robot, base)
    law = None if not d.get("friction_law") else _law_from(d["friction_law"], robot.ndof)
    model = Model("rigid", robot=robot, offset=bool(_field(d, "offset")), coulomb_law=law[0] if law else "algebraic",
                  coulomb_eps=law[1] if law else None, elastic=tuple(d.get("elastic") or ()), terms=_terms_from(d),
                  load_friction=tuple(d.get("load_friction") or ()),
                  backlash_gap=tuple(d["backlash_gap"]) if d.get("backlash_gap") else None)
    # a standard deviation the fit could not give (a held parameter's, a singular covariance) is saved as null
    std = {str(k): math.nan if v is None else v for k, v in dict(_field(d, "std")).items()}
    return robot_result(_field(d, "method"), dict(_field(d, "params")), std, model, base,
                         force_error=d.get("force_error", math.nan),
                         force_error_per_joint=dict(d.get("force_error_per_joint", {})),
                         start_s=float(d.get("start_s") or 0.0),
                         force_error_after_start=float(d.get("force_error_after_start") or math.nan),
                         converged=bool(d.get("converged", True)), iterations=int(d.get("iterations", 0)),
                         message=d.get("message", ""), elapsed_s=float(d.get("elapsed_s", 0.0)),
                         frozen={str(k): float(v) for k, v in (d.get("frozen") or {}).items()},
                         notes=list(d.get("notes", [])), history=iterations_of(d.get("history", [])),
                         options={"controller_check": d.get("controller_check"),
                                  **{k: v for k, v in (d.get("elastic_steps") or {}).items() if k in ELASTIC_OPTIONS}})


def _terms_from(d: Dict[str, Any]) -> tuple:
    """A saved robot result's extra terms (a DataError naming the field where they are not terms)."""
    from .model import Term

    raw = d.get("terms") or []
    if not isinstance(raw, list):
        raise DataError("its field 'terms' is not a list of {name, kind, dof, hypers} objects: save the result again")
    return tuple(Term.from_saved(t) for t in raw)


def _check_robot_parts(d: Dict[str, Any], robot, base) -> None:
    """A saved robot result's base map and parameters fit its robot: the base map's shape (each base parameter a
    combination of the robot's standard parameters: its rotor inertias and ten per body), and every parameter the
    robot's model has, a finite number (a DataError naming the first that is not)."""
    n = robot.ndof
    ns, nb = len(base.standard_names), len(base.names)
    if ns != 11 * n or base.K.shape != (nb, ns) or len(base.independent) != nb or not np.all(np.isfinite(base.K)) \
            or any(not isinstance(i, int) or not 0 <= i < ns for i in base.independent):
        raise DataError(f"its base map does not fit its {n}-joint robot: {nb} base parameters, {ns} standard ones "
                        f"(expected {11 * n}), K of shape {base.K.shape}, {len(base.independent)} independent columns")
    params = d.get("params")
    if not isinstance(params, dict):
        raise DataError("its params are not an object of name: value")
    elastic = [j for j in robot.joint_names if j in (d.get("elastic") or ())]
    names = list(base.names) + [f"{p}_{j}" for p in ("Ia", "Fv", "Fc") + (("OF",) if d.get("offset") else ())
                                for j in robot.joint_names] + [f"{p}_{j}" for p in ("K", "D") for j in elastic]
    names += [t.name for t in _terms_from(d)] + [f"Fl_{j}" for j in robot.joint_names
                                                   if j in (d.get("load_friction") or ())]
    missing = [k for k in names if k not in params]
    if missing:
        raise DataError(f"its params lack {', '.join(missing[:4])}{' …' if len(missing) > 4 else ''} (a parameter "
                        "of its robot's model removed or renamed): save the result again")
    for k in names:
        v = params[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise DataError(f"its parameter {k} is {v!r}, not a finite number")
        params[k] = float(v)  # a whole number written by hand reads as the float it means
    extra = [k for k in params if k not in names]
    if extra:
        raise DataError(f"its params hold {', '.join(map(str, extra[:4]))}, which its robot's model does not have (a "
                        "parameter added or renamed): save the result again")


def _law_from(d: Dict[str, Any], n: int) -> Tuple[str, Tuple[float, ...]]:
    """A saved friction law: its shape and each joint's ε (one ε for every joint in results saved before ε was per
    joint)."""
    eps = d["eps"]
    eps = [float(eps)] * n if isinstance(eps, (int, float)) else [float(e) for e in eps]
    if len(eps) != n:
        raise DataError(f"the saved friction law has {len(eps)} smoothing speeds for {n} joints")
    return (str(d["shape"]), tuple(eps))


def _fmt(x: float) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    a = abs(x)
    if a != 0 and (a >= 1e5 or a < 1e-3):
        return f"{x:.4g}"
    return f"{x:.4g}" if a >= 1000 else f"{x:.4g}"


def _pct(x: float) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.2f}"


def compare(results: Dict[str, IdentificationResult], reference: Optional[str] = None, truth: Optional[Dict[str, float]] = None) -> str:
    """Side-by-side table of several results (like Tables 3 to 6): parameters, the sums M1 + M2, Fv1 + Fv2, Fc1 + Fc2,
    and, with ``reference``, the relative differences %e = 100 (χ − χ_ref)/χ_ref of eq. (34); with ``truth``, a truth column."""
    from ._errors import DataError

    if not isinstance(results, Mapping) or not results:
        raise DataError("compare takes a mapping label -> result, e.g. {'DIDIM': r1, 'OE-LM': r2}")
    bad = [k for k, r in results.items() if not isinstance(r, IdentificationResult)]
    if bad:
        raise DataError(f"compare: {', '.join(map(str, bad))} not a didim result (an IdentificationResult)")
    if reference is not None and reference not in results:
        raise DataError(f"compare: the reference {reference!r} is not one of {', '.join(map(str, results))}")
    if truth is not None and not isinstance(truth, Mapping):
        raise DataError("compare: truth must be a mapping name -> value")
    names: List[str] = []
    for r in results.values():
        for n in list(r.params) + list(r.frozen):
            if n not in names:
                names.append(n)

    def value(r: IdentificationResult, n: str) -> float:
        return r.params.get(n, r.frozen.get(n, float("nan")))

    rows: List[tuple] = [(n, {k: value(r, n) for k, r in results.items()}, truth.get(n) if truth else None) for n in names]
    if {"M1", "M2"} <= set(names):
        for s, (a, b) in {"M1 + M2": ("M1", "M2"), "Fv1 + Fv2": ("Fv1", "Fv2"), "Fc1 + Fc2": ("Fc1", "Fc2")}.items():
            rows.append(
                (
                    s,
                    {k: np.nansum([value(r, a), value(r, b)]) for k, r in results.items()},
                    (truth.get(a, 0) + truth.get(b, 0)) if truth else None,
                )
            )
    cols = list(results)
    w = 20  # label column: name and unit
    units = {k: u for r in results.values() for k, u in r.units.items()}

    def label(name: str) -> str:
        unit = units.get(name.split(" ")[0], UNITS.get(name.split(" ")[0], ""))
        return f"{name} ({unit})" if unit and unit != "-" else name

    head = f"{'parameter':<{w}}" + ("".join(f"{'truth':>12}") if truth else "")
    for c in cols:
        head += f"{c:>14}"
        if reference and c != reference:
            head += f"{'%e':>8}"
    lines = [head, "-" * len(head)]
    for name, vals, tv in rows:
        line = f"{label(name):<{w}}" + (f"{_fmt(tv) if tv is not None else '-':>12}" if truth else "")
        for c in cols:
            line += f"{_fmt(vals[c]):>14}"
            if reference and c != reference:
                ref = vals[reference]
                e = 100 * (vals[c] - ref) / ref if ref and math.isfinite(ref) and math.isfinite(vals[c]) else float("nan")
                line += f"{_pct(e) if math.isfinite(e) else '-':>8}"
        lines.append(line)
    lines.append("-" * len(head))
    lines.append(f"{'rel. error':<{w}}" + (f"{'':>12}" if truth else "") + "".join(
        f"{100 * results[c].relative_error:>13.2f}%" + ("" if not reference or c == reference else f"{'':>8}") for c in cols
    ))
    lines.append(f"{'iterations':<{w}}" + (f"{'':>12}" if truth else "") + "".join(
        f"{results[c].iterations:>14d}" + ("" if not reference or c == reference else f"{'':>8}") for c in cols
    ))
    lines.append(f"{'simulations':<{w}}" + (f"{'':>12}" if truth else "") + "".join(
        f"{results[c].simulations:>14d}" + ("" if not reference or c == reference else f"{'':>8}") for c in cols
    ))
    lines.append(f"{'time (s)':<{w}}" + (f"{'':>12}" if truth else "") + "".join(
        f"{results[c].elapsed_s:>14.3f}" + ("" if not reference or c == reference else f"{'':>8}") for c in cols
    ))
    if reference:
        lines.append(f"(%e = 100 (χ − χ_{reference})/χ_{reference}, eq. (34): against the reference column {reference}, "
                     "not against the truth)")
    return "\n".join(lines)


def load_result(path) -> "IdentificationResult":  # noqa: F821
    """Reloads a result saved as JSON (``result.save("r.json")``, ``didim identify --json``) with its model structure,
    so that ``didim.simulate(rec, load_result("r.json"))`` applies it to another record (the paper's cross-test)."""
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
    if isinstance(d, dict) and d.get("kind") != "robot" and "robot" in d and "base" in d:
        raise DataError(f"{os.fspath(path)}: its field 'kind' is {d.get('kind')!r} but it holds a robot's result "
                        "(fields 'robot' and 'base'): a robot's result has kind 'robot'; save the result again")
    if not isinstance(d, dict) or ("params" not in d or "model" not in d) and d.get("kind") != "robot":
        raise DataError(f"{os.fspath(path)}: not a didim result (needs 'model' and 'params'; save one with "
                        "result.save('r.json') or didim identify --json)")
    try:
        return IdentificationResult.from_dict(d)
    except DataError as e:
        raise DataError(f"{os.fspath(path)}: {e}") from None
    except RecursionError:
        raise DataError(f"{os.fspath(path)}: not a didim result (its steps are nested too deeply)") from None


__all__ = ["IdentificationResult", "Iteration", "compare", "UNITS", "load_result", "robot_result", "iterations_of"]
