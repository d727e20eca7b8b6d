"""The model structure as one object: what a result was identified with and what the simulator needs to reproduce it.

A :class:`Model` is the kind (rigid or flexible), the constant force offset, the extra terms (:class:`Term`, each with
its named hyper-parameters), the actuation delay and force lag, the backlash of the coupling and the Coulomb friction
law. Every method, the doctor and every result take and carry one (``result.structure``); a kind given as text is
converted once, where it enters (:func:`as_model`). Names, units and roles of the parameters come from the core's
model (:meth:`Model.core`), which also builds the simulator's and the regressor's basis functions.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, fields, replace
from typing import Any, Dict, Optional, Tuple, Union

from . import _checks, _core
from ._errors import DataError

MODELS = ("rigid", "flexible")
#: The shapes of the Coulomb sign through zero speed the core knows (``coulomb_law``).
COULOMB_LAWS: Tuple[str, ...] = tuple(_core.COULOMB_LAWS)
#: The actuation options (fields of :class:`Model` of the same names) the core's closed loop takes by name.
ACTUATION: Tuple[str, ...] = tuple(_core.ACTUATION)
#: Degrees of freedom a term can act on (the load only in the flexible model).
TERM_DOFS = ("motor", "load")
#: The core's table of term kinds: kind -> ((hyper-parameter, unit, default or None), ...), and its description.
TERM_HYPERS: Dict[str, Tuple[Tuple[str, str, Optional[float]], ...]] = {k: tuple(h) for k, h, _ in _core.TERM_TABLE}
TERM_DOCS: Dict[str, str] = {k: d for k, _, d in _core.TERM_TABLE}
#: Older kind names, read from saved models: alias -> (kind, {hyper-parameter: fixed value}).
TERM_ALIASES: Dict[str, Tuple[str, Dict[str, float]]] = {a: (k, dict(f)) for a, k, f in _core.TERM_ALIASES}
#: Every kind name a :class:`Term` accepts.
TERM_KINDS: Tuple[str, ...] = tuple(TERM_HYPERS) + tuple(TERM_ALIASES)


@dataclass(frozen=True, init=False)
class Term:
    """An extra term of a model: a parameter ``name`` times a basis function of the state, of a ``kind`` of the core's
    table (:data:`TERM_HYPERS`, :data:`TERM_DOCS`) with its hyper-parameters by name (SI units, load side):

    - ``offset``: 1 (N); ``viscous``: q̇; ``coulomb``: sign(q̇);
    - ``abs_viscous``: |q̇| and ``abs_coulomb``: |sign(q̇)|, friction that depends on the direction of motion;
    - ``stribeck``: sign(q̇)·exp(−(q̇/vs)²), ``vs`` (m/s);
    - ``ripple``: sin(2π q/period + phase), ``period`` (m), ``phase`` (rad, 0 by default; π/2 for the cosine);
    - ``coulomb_ripple``: sign(q̇)·sin(2π q/period + phase): Coulomb friction that varies along the stroke;
    - ``coulomb_spline``: B((q − center)/width)·σ(q̇), ``center`` and ``width`` (m), ``side`` 1 forward, −1 backward,
      0 both (the default): a friction profile along the stroke, B the cubic B-spline (B-splines ``width`` apart sum
      to 1), σ the forward or backward part of sign(q̇), smooth through rest; with ``lo < hi``, q is held within
      [lo, hi] (the profile keeps its end values beyond the stroke it was fitted on; ``lo = hi = 0``: no limit);
    - ``spline``: B((q − center)/width), ``center`` and ``width`` (m): a force profile along the stroke whatever the
      motion (a counterbalance's, a cable's), one knot's share; ``lo``, ``hi`` as for ``coulomb_spline``;
    - ``gravity``: sin(q + angle_offset + phase) (N·m), q the joint angle (rad); ``A sin(q) + B cos(q)`` is two terms,
      ``phase`` 0 and π/2;
    - ``damper`` (flexible model): coupling damping in parallel with K12 (N/(m/s)).

    ``Term("Fs", "stribeck", vs=0.017)``; a kind's first hyper-parameter may be given by position
    (``Term("Fs", "stribeck", 0.017)``). ``dof``: "motor" (default) or "load" (flexible model); a damper couples the
    two. On a robot, ``dof`` is the joint's name (``Term("Fs_elbow", "stribeck", vs=0.05, dof="elbow_joint")``; its
    hyper-parameters in the joint's units, rad or m): the term acts on that joint where its friction acts (the rotor
    of an elastic joint), at its position and speed; ``gravity`` there is a torque along the joint's stroke such as a
    counterbalance's or a cable's, ``A sin(q + φ)`` as two terms. The older names ``ripple_sin``/``ripple_cos``, ``coulomb_ripple_sin``/``_cos`` and
    ``coulomb_spline_fwd``/``_bwd`` are read as their kind with the phase or side they fixed.
    """

    name: str
    kind: str
    dof: str
    hyper_values: Tuple[Tuple[str, float], ...]

    def __init__(self, name: str, kind: str, hyper: Optional[float] = None, dof: str = "motor",
                 width: Optional[float] = None, **hypers: float):
        if not isinstance(name, str) or not name:
            raise DataError(f"a term's name must be a non-empty text, got {name!r}")
        if not isinstance(kind, str) or kind not in TERM_KINDS:
            raise DataError(f"unknown term kind {kind!r}: use one of {', '.join(TERM_HYPERS)}")
        base, fixed = TERM_ALIASES.get(kind, (kind, {}))
        table = TERM_HYPERS[base]
        given = dict(hypers)
        free = [h for h, _, _ in table if h not in fixed]
        if hyper is not None:
            if not free:
                if hyper != 0:  # saved models of older releases give 0 for kinds without one
                    raise DataError(f"term {name}: a {kind} term has no hyper-parameter, got {hyper!r}")
            elif free[0] in given:
                raise DataError(f"term {name}: {free[0]} given twice (by position and by name)")
            else:
                given[free[0]] = hyper
        if width is not None and not (width == 0 and "width" not in free):
            if "width" not in free:
                raise DataError(f"term {name}: only spline terms have a width (knot spacing); leave it out for a "
                                f"{kind} term")
            given["width"] = width
        for h, v in given.items():
            if h not in [t[0] for t in table]:
                names = ", ".join(t[0] for t in table) or "none"
                raise DataError(f"term {name}: a {kind} term's hyper-parameters are {names}, got {h!r}")
            if h in fixed and v != fixed[h]:
                raise DataError(f"term {name}: a {kind} term has {h} = {fixed[h]:g}; give a {base} term for another {h}")
        values = []
        for h, unit, default in table:
            v = given.get(h, fixed.get(h, default))
            if v is None:
                example = ", ".join(f"{t}=..." for t, _, d in table if d is None)
                raise DataError(f"term {name}: a {base} term needs its {h} ({unit}): e.g. didim.Term({name!r}, "
                                f"{base!r}, {example})")
            values.append((h, _checks.real(f"term {name}'s {h}", v, unit)))
        if not isinstance(dof, str) or not dof:
            raise DataError(f"term {name}'s dof is 'motor' or 'load' on one axis, a joint's name on a robot; got {dof!r}")
        if base == "damper" and dof != "motor":
            raise DataError(f"term {name}: a damper couples the motor and the load; leave its dof out")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "kind", base)
        object.__setattr__(self, "dof", dof)
        object.__setattr__(self, "hyper_values", tuple(values))
        # the core checks the values (a Stribeck speed > 0, a knot spacing > 0, a side in {-1, 0, 1}); under one
        # name for every term, so that the same kind and values are checked once (a doctor's round builds thousands),
        # and again under the term's own name where they fail, for the message
        plant = "flexible" if dof == "load" or base == "damper" else "rigid"
        try:
            _core_model(plant, False, (_freeze(("term", *self.axis_spec()[1:])),), None, 1.0, "algebraic")
        except DataError:
            _core_model(plant, False, (_freeze(self.axis_spec()),), None, 1.0, "algebraic")
            raise

    @property
    def hypers(self) -> Dict[str, float]:
        """The hyper-parameters by name (SI units, load side)."""
        return dict(self.hyper_values)

    def __repr__(self) -> str:
        h = "".join(f", {k}={v!r}" for k, v in self.hyper_values)
        return f"Term({self.name!r}, {self.kind!r}{h}{'' if self.dof == 'motor' else f', dof={self.dof!r}'})"

    def spec(self) -> tuple:
        """(name, kind, dof, [(hyper-parameter, value), ...]), as the core takes it."""
        return (self.name, self.kind, self.dof, list(self.hyper_values))

    def axis_spec(self) -> tuple:
        """:meth:`spec` on one axis's dof: a robot joint's term as the same term on a one-axis model's motor (the
        core's basis function of the joint's own position and speed)."""
        return (self.name, self.kind, self.dof if self.dof in TERM_DOFS else "motor", list(self.hyper_values))

    def to_dict(self) -> Dict[str, Any]:
        return {"name": self.name, "kind": self.kind, "dof": self.dof, "hypers": dict(self.hyper_values)}

    @classmethod
    def from_saved(cls, t) -> "Term":
        """A term as a saved model holds it: {"name", "kind", "dof", "hypers"}, or the [name, kind, hyper, dof, width]
        list of older releases."""
        if isinstance(t, Term):
            return t
        if isinstance(t, dict):
            unknown = set(t) - {"name", "kind", "dof", "hypers"}
            if unknown or not isinstance(t.get("hypers", {}), dict):
                raise DataError(f"a saved term is {{name, kind, dof, hypers}}, got {t!r}")
            return cls(t.get("name"), t.get("kind"), dof=t.get("dof", "motor"), **t.get("hypers", {}))
        if isinstance(t, (list, tuple)) and 2 <= len(t) <= 5:
            return cls(*t)
        raise DataError(f"a model term is a didim.Term or a {{name, kind, dof, hypers}} object, got {t!r}")


@functools.lru_cache(maxsize=512)
def _core_model(kind: str, offset: bool, specs: tuple, backlash_gap: Optional[float], coulomb_eps: float,
                coulomb_law: str, actuation: tuple = ()) -> "_core.Model":
    """The core's model of a structure, built once per structure (identification loops ask at every step)."""
    return _core.Model(kind, offset=offset, terms=[(n, k, d, list(h)) for n, k, d, h in specs] or None,
                       backlash_gap=backlash_gap, coulomb_eps=coulomb_eps, coulomb_law=coulomb_law,
                       actuation=list(actuation))


def _freeze(spec: tuple) -> tuple:
    n, k, d, h = spec
    return (n, k, d, tuple(h))


@dataclass(frozen=True)
class Model:
    """A model structure. ``kind``: "rigid" (eq. (6), M, Fv, Fc) or "flexible" (eq. (2), M1, Fv1, Fc1, M2, Fv2, Fc2,
    K12); ``offset``: a constant force OF (N); ``terms``: extra :class:`didim.Term` s (each on the motor or the load);
    ``force_lag``: time constant (s) of a first-order lag from the command to the applied force; ``delay``: actuation delay in
    samples; ``backlash_gap``: total width (m) of a dead zone in K12 (flexible only; a robot's: one per joint, rad or
    m, on elastic joints only, 0 for none, or ``{joint: width}``); ``coulomb_eps``: velocity scale
    (m/s or rad/s) of the smoothed Coulomb sign, 0 for the hard sign, None for the record's
    (:func:`didim.simulation.default_coulomb_eps`; an identified model carries the number it was fitted with).

    ``robot``: the link side of a robot (:class:`didim.Robot`, a URDF's rigid-body chain), None for one axis's lumped
    mass. A robot's model gives each joint its drive (rotor inertia ``Ia``, ``Fv``, ``Fc`` and, with ``offset``,
    ``OF``); ``elastic`` names the joints whose transmission is a spring ``K`` with damping ``D`` between the rotor
    (``Ia``, the friction and the drive's force, on the motor side the encoder reads) and the link (its kind is then
    "flexible"; a rigid joint's rotor moves with its link); its ``coulomb_eps`` is one smoothing speed per joint
    (rad/s or m/s), None to fit the law from the record; its drives' delay and force lag are each joint's, in the
    controller file (the record's)."""

    kind: str = "rigid"
    offset: bool = False
    terms: Tuple[Term, ...] = field(default_factory=tuple)
    delay: int = 0
    backlash_gap: Union[None, float, Tuple[float, ...]] = None
    force_lag: float = 0.0
    coulomb_eps: Union[None, float, Tuple[float, ...]] = None
    coulomb_law: str = "algebraic"
    robot: Optional[Any] = None
    elastic: Tuple[str, ...] = ()
    load_friction: Tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in MODELS:
            raise DataError(f"unknown model kind {self.kind!r}: use one of {', '.join(MODELS)}")
        if not isinstance(self.kind, str) or not isinstance(self.terms, (tuple, list)):
            raise DataError(f"a model needs a kind (text) and a list of terms, got {self.kind!r}, {self.terms!r}")
        object.__setattr__(self, "terms", tuple(Term.from_saved(t) for t in self.terms))
        object.__setattr__(self, "offset", _checks.flag("offset", self.offset))
        if self.backlash_gap is not None and self.robot is None:
            object.__setattr__(self, "backlash_gap", _checks.real("backlash_gap", self.backlash_gap, "m", lo=0.0))
        object.__setattr__(self, "delay", _checks.whole("delay", self.delay, hint=" (samples)"))
        object.__setattr__(self, "force_lag", _checks.real("force_lag", self.force_lag, "s", lo=0.0, lo_open=False))
        _checks.one_of("coulomb_law", self.coulomb_law, COULOMB_LAWS)
        if self.robot is not None:
            self._check_robot()
            return
        bad = [t for t in self.terms if t.dof not in TERM_DOFS]
        if bad:
            raise DataError(f"term {bad[0].name}'s dof is {bad[0].dof!r}: one axis's terms act on the 'motor' or the "
                            "'load' (a joint's name is a robot's: didim.Model(robot=...))")
        if self.elastic:
            raise DataError("elastic names a robot's elastic joints; one axis's two masses are the 'flexible' kind "
                            "(didim.Model('flexible'))")
        elif self.load_friction:
            raise DataError("load_friction names a robot's joints whose friction grows with their torque; one axis has "
                            "no chain to carry a load")
        elif self.coulomb_eps is not None:
            object.__setattr__(self, "coulomb_eps", _checks.real("coulomb_eps", self.coulomb_eps, "m/s", lo=0.0,
                                                                 lo_open=False))

    def _check_robot(self) -> None:
        """A robot's model: its chain, rigid, each joint's drive; what one axis's model has and a robot's has not yet
        is refused, naming where it goes."""
        from .robots.chain import Robot

        robot = self.robot
        if not isinstance(robot, Robot):
            raise DataError(f"a model's robot is a didim.Robot (didim.Robot.from_urdf(path)), got "
                            f"{type(robot).__name__}")
        object.__setattr__(self, "elastic", self._joint_names(robot, self.elastic, "elastic"))
        object.__setattr__(self, "load_friction", self._joint_names(robot, self.load_friction, "load_friction"))
        if self.kind == "flexible" and not self.elastic:
            raise DataError("a robot's flexible model names its elastic joints: elastic=['joint', ...] (CLI: "
                            "--elastic J1,J2 or --elastic all)")
        if self.kind not in ("rigid", "flexible"):
            raise DataError(f"a robot's model is rigid, or flexible with elastic joints, got {self.kind!r}")
        object.__setattr__(self, "kind", "flexible" if self.elastic else "rigid")
        given = [name for name, v in (("delay", self.delay), ("force_lag", self.force_lag)) if v]
        if given:
            raise DataError(f"a robot's model takes no {', '.join(given)}: each joint's delay and force lag go in its "
                            "entry of the controller file (\"delay\", \"force_lag\")")
        self._check_backlash(robot)
        self._check_joint_terms(robot)
        if self.coulomb_eps is not None:
            eps = self.coulomb_eps
            if not isinstance(eps, (tuple, list)) or len(eps) != robot.ndof:
                raise DataError(f"a robot's coulomb_eps is one smoothing speed per joint ({robot.ndof}: "
                                f"{', '.join(robot.joint_names)}), got {eps!r}")
            object.__setattr__(self, "coulomb_eps", tuple(
                _checks.real(f"joint {j}'s coulomb_eps", e, "rad/s or m/s", lo=0.0, lo_open=False)
                for j, e in zip(robot.joint_names, eps)))

    def _check_backlash(self, robot) -> None:
        """A robot's ``backlash_gap``: each elastic joint's dead zone between rotor and link (total width, rad or m),
        given as one value per joint (0 on a joint without) or as ``{joint: gap}``; kept as one per joint, or None
        when no joint has one."""
        gaps = self.backlash_gap
        if gaps is None:
            return
        names = list(robot.joint_names)
        if isinstance(gaps, dict):
            # joints by name or 1-based number, as elastic takes them; one joint named twice is refused
            by_name: Dict[str, Any] = {}
            for key, value in gaps.items():
                name = self._joint_names(robot, [key], "backlash_gap (--backlash)")[0]
                if name in by_name:
                    raise DataError(f"backlash_gap (--backlash) names the joint {name} twice: give each joint's width once")
                by_name[name] = value
            gaps = [by_name.get(j, 0.0) for j in names]
        if not isinstance(gaps, (tuple, list)) or len(gaps) != robot.ndof:
            raise DataError(f"a robot's backlash_gap is one total width per joint ({robot.ndof}: {', '.join(names)}; "
                            f"0 for none) or {{joint: width}}, got {gaps!r}")
        out = tuple(_checks.real(f"joint {j}'s backlash_gap", g, "rad or m", lo=0.0, lo_open=False)
                    for j, g in zip(names, gaps))
        rigid = [j for j, g in zip(names, out) if g > 0 and j not in self.elastic]
        if rigid:
            raise DataError(f"backlash_gap (--backlash) on {', '.join(rigid)}, which "
                            f"{'is' if len(rigid) == 1 else 'are'} rigid: backlash is a dead zone between an elastic "
                            "joint's rotor and its link (name it elastic: elastic=[...], --elastic)")
        object.__setattr__(self, "backlash_gap", out if any(g > 0 for g in out) else None)

    @property
    def gaps(self) -> Tuple[float, ...]:
        """A robot's backlash per joint (total width, rad or m; 0 for none)."""
        if self.robot is None:
            raise DataError("gaps is a robot's backlash per joint; one axis's is backlash_gap")
        return tuple(self.backlash_gap) if self.backlash_gap is not None else (0.0,) * self.robot.ndof

    def with_backlash(self, joint: str, gap: Optional[float]) -> "Model":
        """This robot's model with elastic joint ``joint``'s backlash set to the total width ``gap`` (rad or m; None
        or 0: none)."""
        gaps = dict(zip(self.robot.joint_names, self.gaps))
        gaps[joint] = float(gap or 0.0)
        return replace(self, backlash_gap=gaps)

    #: The term kinds a robot's joint takes: those of one dof (a spring or damper couples two).
    JOINT_TERM_KINDS = ("offset", "viscous", "coulomb", "abs_viscous", "abs_coulomb", "stribeck", "ripple",
                        "coulomb_ripple", "coulomb_spline", "spline", "gravity")

    def _check_joint_terms(self, robot) -> None:
        """Each term of a robot's model names one of its joints (``dof``) and is of a kind one joint takes; the
        names are unique and none is a drive's own parameter's."""
        names = list(robot.joint_names)
        own = {f"{p}_{j}" for p in ("Ia", "Fv", "Fc", "OF", "K", "D", "Fl") for j in names}
        seen = set()
        for t in self.terms:
            if t.kind not in self.JOINT_TERM_KINDS:
                raise DataError(f"term {t.name}: a {t.kind} term couples two dofs; a robot joint's terms are of the "
                                f"kinds {', '.join(self.JOINT_TERM_KINDS)} (an elastic joint: elastic=[...])")
            if t.dof not in names:
                raise DataError(f"term {t.name}: on a robot a term's dof is the joint it acts on, one of "
                                f"{', '.join(names)}; got {t.dof!r}")
            if t.name in seen or t.name in own:
                raise DataError(f"term {t.name}: the name is taken (each term's name is its parameter's: unique, "
                                "and none of the drives' Ia_, Fv_, Fc_, OF_, K_, D_, Fl_)")
            seen.add(t.name)

    @staticmethod
    def _joint_names(robot, given, what: str) -> Tuple[str, ...]:
        """``elastic`` or ``load_friction`` (``what``) as the robot's joint names in its order: names, 1-based
        numbers, or ``"all"``."""
        if isinstance(given, str):
            given = robot.joint_names if given.strip() == "all" else [x.strip() for x in given.split(",") if x.strip()]
        if not isinstance(given, (tuple, list)):
            raise DataError(f"{what} is a list of the robot's joint names (or 'all'), got {type(given).__name__}")
        names = list(robot.joint_names)
        out: Dict[str, Any] = {}
        for g in given:
            if isinstance(g, str) and g in names:
                name = g
            elif isinstance(g, (int, str)) and str(g).isdigit() and 1 <= int(g) <= len(names):
                name = names[int(g) - 1]
            else:
                raise DataError(f"{what}: {g!r} is not a joint of the robot {robot.name} ({', '.join(names)}; or "
                                f"their numbers 1..{len(names)}, or 'all')")
            if name in out:  # a joint named twice is a slip for another joint: which one only the user knows
                raise DataError(f"{what} names the joint {name} twice ({out[name]!r} and {g!r}): name each joint once "
                                f"(the robot {robot.name}'s joints: {', '.join(names)})")
            out[name] = g
        return tuple(j for j in names if j in out)

    @property
    def law(self) -> Optional[Tuple[str, Tuple[float, ...]]]:
        """A robot's friction law through zero speed: its shape and each joint's smoothing speed (None until fitted)."""
        if self.robot is None or self.coulomb_eps is None:
            return None
        return (self.coulomb_law, tuple(self.coulomb_eps))  # type: ignore[arg-type]

    def with_law(self, law: Tuple[str, Tuple[float, ...]]) -> "Model":
        """This robot's model with the friction law ``law`` (shape, each joint's ε)."""
        return replace(self, coulomb_law=law[0], coulomb_eps=tuple(law[1]))

    def describe(self) -> str:
        """In words: the kind and every structure field that is not the default."""
        if self.robot is not None:
            return (f"{self.kind} model of the {self.robot.ndof}-joint robot {self.robot.name}"
                    + (f" with elastic joints {', '.join(self.elastic)}" if self.elastic else "")
                    + (f", load-dependent friction on {', '.join(self.load_friction)}" if self.load_friction else "")
                    + (", backlash " + ", ".join(f"{g:.3g} on {j}" for j, g in zip(self.robot.joint_names, self.gaps)
                                                 if g > 0) if self.backlash_gap is not None else "")
                    + (" with an offset per joint" if self.offset else "")
                    + (f", terms {', '.join(f'{t.name} ({t.kind} on {t.dof})' for t in self.terms)}" if self.terms
                       else "")
                    + (f", {self.coulomb_law} friction law" if self.law is not None else ""))
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

    def core(self, coulomb_eps: Optional[float] = None) -> "_core.Model":
        """The core's model of this structure (names, units, roles, regressor; what the simulator integrates), with
        ``coulomb_eps`` for a structure whose smoothing is the record's (``self.coulomb_eps`` None)."""
        if self.robot is not None:
            raise DataError("a robot's model has no one-axis core model: its chain is the robot's (didim.Robot)")
        eps = self.coulomb_eps if self.coulomb_eps is not None else coulomb_eps
        return _core_model(self.kind, self.offset, tuple(_freeze(t.spec()) for t in self.terms), self.backlash_gap,
                           _core.DEFAULT_COULOMB_EPS if eps is None else float(eps), self.coulomb_law,
                           tuple((a, float(getattr(self, a))) for a in ACTUATION))

    def param_names(self) -> list:
        """Parameter names in the order of the parameter vector."""
        return list(self.core().names)

    def units(self) -> Dict[str, str]:
        """Unit of each parameter (SI, load side), as the core's basis functions give them. A robot's: each joint's
        drive parameters and terms in its own units (N·m·s/rad on a revolute joint, N·s/m on a prismatic one) and the
        bodies' standard parameters (m kg, mx kg·m, Ixx kg·m²)."""
        if self.robot is not None:
            return self._robot_units()
        return dict(zip(self.core().names, self.core().units))

    def _robot_units(self) -> Dict[str, str]:
        """Each parameter's SI unit as one axis names it (m, N on the load side: "N/(m/s)"), the joint it belongs to
        saying whether it reads per rad (:attr:`didim.IdentificationResult.units` names them so); the bodies'
        standard parameters in their own (m kg, mx kg·m, Ixx kg·m²)."""
        out: Dict[str, str] = {}
        for j in self.robot.joint_names:
            for p, si in (("Ia", "kg"), ("Fv", "N/(m/s)"), ("Fc", "N"), ("OF", "N"), ("K", "N/m"), ("D", "N/(m/s)")):
                out[f"{p}_{j}"] = si
            out[f"Fl_{j}"] = "-"
        for name in self.robot.param_names:
            out[name] = {"m": "kg", "mx": "kg·m", "my": "kg·m", "mz": "kg·m"}.get(name.split("_")[0], "kg·m²")
        for t in self.terms:
            core = _core_model("rigid", False, (_freeze(t.axis_spec()),), None, 1.0, "algebraic")
            out[t.name] = dict(zip(core.names, core.units))[t.name]
        return out

    def joint_of(self, name: str) -> Optional[str]:
        """The robot joint a drive parameter or term belongs to (None for a body's parameter or one axis's)."""
        if self.robot is None:
            return None
        term = next((t for t in self.terms if t.name == name), None)
        if term is not None:
            return term.dof
        head, _, rest = name.partition("_")
        return rest if head in ("Ia", "Fv", "Fc", "OF", "K", "D", "Fl") and rest in self.robot.joint_names else None

    def roles(self) -> Dict[str, str]:
        """What each parameter is ("mass", "friction", "stiffness", "damping", "force"), from the core."""
        return dict(zip(self.core().names, self.core().roles))

    def with_terms(self, *terms: Term) -> "Model":
        """This structure with more terms."""
        return replace(self, terms=self.terms + tuple(terms))

    def to_dict(self) -> Dict[str, Any]:
        out = {"kind": self.kind, "offset": self.offset, "terms": [t.to_dict() for t in self.terms],
               "delay": self.delay, "force_lag": self.force_lag,
               "backlash_gap": list(self.backlash_gap) if isinstance(self.backlash_gap, tuple) else self.backlash_gap,
               "coulomb_eps": list(self.coulomb_eps) if isinstance(self.coulomb_eps, tuple) else self.coulomb_eps,
               "coulomb_law": self.coulomb_law}
        if self.robot is not None:
            out["robot"] = {"name": self.robot.name, "joints": self.robot.joint_names, "urdf": self.robot.urdf}
            if self.elastic:
                out["elastic"] = list(self.elastic)
            if self.load_friction:
                out["load_friction"] = list(self.load_friction)
        return out

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "Model":
        if not isinstance(d, dict):
            raise DataError(f"a model structure must be a JSON object, got {type(d).__name__}")
        unknown = set(d) - {"kind", "offset", "terms", "delay", "force_lag", "backlash_gap", "coulomb_eps",
                             "coulomb_law", "robot", "elastic", "load_friction"}
        if unknown:
            raise DataError(f"unknown model field(s) {', '.join(sorted(unknown))}")
        raw = d.get("terms") or []
        if not isinstance(raw, list):
            raise DataError("model terms must be a list of {name, kind, dof, hypers} objects")
        terms = tuple(Term.from_saved(t) for t in raw)
        offset = d.get("offset", False)
        if not isinstance(offset, bool):
            raise DataError(f"model field offset must be true or false, got {offset!r}")
        robot, eps = None, d.get("coulomb_eps")
        if d.get("robot") is not None:
            from .robots.chain import Robot

            r = d["robot"]
            if not isinstance(r, dict) or not isinstance(r.get("urdf"), str) or not isinstance(r.get("joints"), list):
                raise DataError("a saved robot model's robot is {name, joints, urdf} (the URDF's text)")
            robot = Robot.from_urdf_string(r["urdf"], r["joints"])
            eps = tuple(eps) if isinstance(eps, list) else eps
            gaps = d.get("backlash_gap")
            d = {**d, "backlash_gap": tuple(gaps) if isinstance(gaps, list) else gaps}
        return cls(kind=d.get("kind", "rigid"), offset=offset, terms=terms, delay=d.get("delay", 0),
                   force_lag=d.get("force_lag", 0.0),
                   backlash_gap=d.get("backlash_gap"), coulomb_eps=eps,
                   coulomb_law=d.get("coulomb_law", "algebraic"), robot=robot,
                   elastic=tuple(d.get("elastic") or ()), load_friction=tuple(d.get("load_friction") or ()))

    @classmethod
    def of_result(cls, kind: str, params: Dict[str, float], options: Dict[str, Any]) -> Optional["Model"]:
        """The structure a method's options describe, for a result made without one: None for results that are not
        parameter sets of a model (step 2's λ, f_n_flex). Every method of didim sets the structure it fitted; this
        reads results saved by releases that did not."""
        if kind not in MODELS:
            return None
        terms = tuple(Term.from_saved(t) for t in options.get("terms") or ())
        m = cls(kind=kind, offset=bool(options.get("offset", False)), terms=terms,
                delay=int(options.get("delay") or 0), force_lag=float(options.get("force_lag") or 0.0),
                backlash_gap=options.get("backlash_gap"), coulomb_eps=options.get("coulomb_eps"),
                coulomb_law=options.get("coulomb_law", "algebraic"))
        return m if set(m.param_names()) >= set(params) else None


def dead_zone(x, gap: float):
    """``sign(x)·max(|x| − gap/2, 0)``: the elongation of a coupling with backlash of total width ``gap``, elementwise
    (the core's ``dead_zone``, which one axis's K12 with backlash and a robot's elastic joint simulate)."""
    import numpy as np

    x = np.asarray(x, dtype=float)
    return np.sign(x) * np.maximum(np.abs(x) - 0.5 * gap, 0.0)


def knot_weights(terms, q):
    """``B((q − center)/width)`` of each ``coulomb_spline`` term at the positions ``q`` (n,), held within its
    ``lo``, ``hi``: its weight along the stroke, whatever its side, from the core's basis function (the term moving
    forward at full speed, hard sign). Shape (n, len(terms))."""
    import numpy as np

    q = np.asarray(q, dtype=float)[None, :]
    both = [Term(t.name, t.kind, **{h: v for h, v in t.hypers.items() if h != "side"}) for t in terms]
    w = Model("rigid", terms=both, coulomb_eps=0.0).core().regressor(q, np.ones_like(q), np.zeros_like(q))
    return w[0, :, 3:]


#: The structure fields of a :class:`Model` beside its kind, as the methods' entry points take them by keyword.
STRUCTURE_FIELDS: Tuple[str, ...] = tuple(f.name for f in fields(Model) if f.name not in ("kind", "robot"))


#: The structure fields :func:`as_model` takes, with the values that mean "not given".
_ENTRY_DEFAULTS: Dict[str, Any] = {**{f.name: f.default for f in fields(Model) if f.name not in ("kind", "terms", "robot")},
                                   "offset": None, "terms": ()}


def as_model(model, **structure) -> Model:
    """A model given where it enters didim, once: a :class:`Model` as it is (giving a structure field again, set to
    anything but its default, is an error naming it), or a kind ("rigid", "flexible") with the structure fields
    (``offset``, ``terms``, ``delay``, ``force_lag``, ``backlash_gap``, ``coulomb_eps``, ``coulomb_law``), or a
    robot (:class:`didim.Robot`): its rigid model, with an offset per joint unless ``offset=False`` (a robot's joints
    carry a constant torque: a cable, what gravity compensation leaves; without it the friction takes it, on the data
    folder's UR5 Fv 7.8 % off instead of 0.24 %)."""
    from .robots.chain import Robot

    defaults = _ENTRY_DEFAULTS
    unknown = set(structure) - set(defaults)
    if unknown:
        raise DataError(f"unknown model field(s) {', '.join(sorted(unknown))}")
    if isinstance(model, Model):
        again = [k for k, v in structure.items()
                 if not (v is None or (k != "offset" and v == defaults[k]) or (isinstance(v, (tuple, list)) and not v)
                         or (k == "offset" and bool(v) == model.offset))]
        if again:
            raise DataError(f"a didim.Model ({model.describe()}) carries its structure: leave {', '.join(again)} out, "
                            "or give the model's kind as text with the structure you want")
        return model
    given = {k: v for k, v in structure.items() if v is not None}
    if isinstance(model, Robot):
        given["offset"] = bool(given.get("offset", True))
        return Model("rigid", robot=model, **given)
    if not isinstance(model, str) or model not in MODELS:
        raise DataError(f"unknown model {model!r}: use one of {', '.join(MODELS)}, a didim.Model or a didim.Robot")
    given["offset"] = bool(given.get("offset", False))
    given["terms"] = tuple(given.get("terms") or ())
    return Model(model, **given)


__all__ = ["Model", "Term", "as_model", "knot_weights", "ACTUATION", "STRUCTURE_FIELDS", "MODELS", "TERM_KINDS", "TERM_HYPERS", "COULOMB_LAWS"]
