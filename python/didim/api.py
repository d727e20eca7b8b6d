"""One entry point for every identification method."""

from __future__ import annotations

import time
import warnings
from dataclasses import replace
from typing import Dict, Optional, Union

import numpy as np

from . import _checks
from ._parallel import serial_blas
from ._errors import DataError, DidimWarning
from .model import STRUCTURE_FIELDS, Model, as_model
from .methods.identification import (Progress, a_priori_mass, didim_flexible, didim_iterate, didim_rigid, idim_ls,
                             method_supports, supports)
from .methods.oe import CRITERIA, oe_lm, oe_nm, pseudo_regular_initial
from .recording import Recording
from .result import IdentificationResult
from .simulation import MODELS

METHODS = ("idim-ls", "didim", "oe-nm", "oe-lm", "oe-gn")
#: Other names of the methods: "oe-gn" is the exact-sensitivity Levenberg-Marquardt solver's former name.
ALIASES = {"oe-gn": "oe-lm"}


def check_options(model: str, method: str, options) -> None:
    """Refuses options that ``method`` on ``model`` does not take (a DataError listing the ones it does)."""
    method = ALIASES.get(method, method)
    if method not in METHODS:
        raise DataError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    funcs, fixed = _targets(model, method)
    named = ("apM", "initial", "criterion", "offset")  # identify's own keywords
    own = {"idim-ls": ("offset",), "didim": ("apM", "offset")}.get(method, named)
    _checks.known_options(funcs, {k: v for k, v in options.items() if k not in named},
                          f"method {method!r} ({model} model)", skip=fixed, also=own)


def _targets(model: str, method: str):
    """The functions ``identify`` hands a method's options to, and the keywords it sets itself."""
    return {
        "idim-ls": ([idim_ls], ("offset",)),
        "didim": ([didim_rigid, didim_iterate] if model == "rigid" else [didim_flexible],
                  ("offset", "model", "progress", "frozen", "method")),
        "oe-nm": ([oe_nm], ("criterion", "progress")),
        "oe-lm": ([oe_lm], ("criterion", "progress")),
    }[method]


def check_sampling(recording: Recording, model: str, method: str, options) -> None:
    """Every low-pass cutoff the method will use (``*_hz`` keywords, given or default) must lie below the record's
    Nyquist frequency; otherwise a DataError says which cutoff, whether it is a default, and what to check."""
    import inspect

    nyquist = recording.fs / 2
    for func in _targets(model, ALIASES.get(method, method))[0]:
        for name, par in inspect.signature(func).parameters.items():
            if not name.endswith("_hz"):
                continue
            given = name in options
            value = options[name] if given else par.default
            if isinstance(value, (int, float)) and not isinstance(value, bool) and value >= nyquist:
                raise DataError(
                    f"{recording.name or 'record'}: sampled at {recording.fs:g} Hz (dt = {recording.dt:g} s), its "
                    f"Nyquist frequency {nyquist:g} Hz lies below {method}'s "
                    f"{'' if given else 'default '}{name} = {value:g} Hz. Drive loops are logged at 1 kHz or more: "
                    "check the time column's unit (milliseconds read as seconds?) or dt; if the rate is right, give a "
                    f"{name} below {nyquist:g} Hz (Python: {name}=…, CLI: --set {name}=…)")


@serial_blas
def identify(
    recording: Recording,
    model: Union[str, Model] = "rigid",
    method: str = "didim",
    *,
    offset: Optional[bool] = None,
    apM: Optional[float] = None,
    initial: Optional[Dict[str, float]] = None,
    criterion: str = "force",
    progress: Progress = None,
    controller_check: str = "error",
    **options,
) -> IdentificationResult:
    """Identifies the ``model`` ("rigid" or "flexible", or a :class:`didim.Model` with its structure: offset, terms,
    delay, backlash, Coulomb smoothing) of a recording with ``method``:

    - ``"idim-ls"``: inverse model on measured positions (the flexible model needs the load position ``ql``);
    - ``"didim"``: rigid DIDIM, or for "flexible" the three-step procedure (rigid DIDIM, Nelder-Mead on
      (λ, f_n_flex), flexible DIDIM);
    - ``"oe-nm"``: Nelder-Mead on all parameters, criterion J_τ ("force") or J_q ("position"), eq. (32);
    - ``"oe-lm"`` (also ``"oe-gn"``): Levenberg-Marquardt with exact closed-loop sensitivities.

    The output-error methods start, unless ``initial`` is given, from (apM, 0, 0) for the rigid model; for the flexible
    one oe-nm starts from the pseudo-regular values of eq. (33) built on a rigid DIDIM (as the paper) and oe-lm from
    the three-step DIDIM estimate (eq. (33) when DIDIM does not converge); their simulations are counted.
    ``apM`` is the a priori total mass (kg); by default :func:`didim.methods.identification.a_priori_mass` estimates it from
    the data (a rigid fit on low-passed signals). Other keyword
    options go to the method's function (e.g. ``cutoff_hz``, ``tol``, ``max_iter``, ``substeps``).

    Raises :class:`DataError` for a bad option or parameter (an unknown option lists the accepted ones),
    :class:`IdentifiabilityError` when the record excites nothing (constant reference) or the regressor is rank
    deficient, :class:`SimulationError` when the loop diverges from the start. Issues a :class:`DidimWarning` for
    each finding of :meth:`Recording.diagnose` (saturated command, force scale not matching the controller). A
    method that stops without converging returns ``converged=False`` with a message and its history.

    ``controller_check``: before any fit, the record's controller applied to the logged reference and position must
    give the logged force (:func:`didim.check.check_controller`); "error" (default) refuses a controller that does
    not, naming the likely mistake, "warn" goes on with a :class:`DidimWarning`, "off" skips the check. The check is
    in the result's ``options["controller_check"]``.
    """
    from .robots import Robot

    if _robot_plant(model, recording):
        return _identify_robot(recording, model, method, offset=offset, apM=apM, initial=initial, criterion=criterion,
                               progress=progress, controller_check=controller_check, **options)
    if not isinstance(model, Model) and (not isinstance(model, str) or model not in MODELS):
        raise DataError(f"unknown model {model!r}: use one of {', '.join(MODELS)} or a didim.Model")
    # the model, converted once: a didim.Model, or a kind with its structure fields as options
    if offset is not None:
        offset = _checks.flag("offset", offset)
    # IDIM-LS's coulomb_eps is its own option (the benchmark's hard sign by default), not the simulator's
    fields = [k for k in STRUCTURE_FIELDS if not (k == "coulomb_eps" and ALIASES.get(method, method) == "idim-ls")]
    structure = as_model(model, offset=offset or None, **{k: options.pop(k) for k in fields if k in options})
    model, offset = structure.kind, structure.offset
    if not isinstance(method, str) or method not in METHODS:
        raise DataError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    method = ALIASES.get(method, method)
    if not isinstance(recording, Recording):
        raise DataError(f"recording must be a didim.Recording (see didim.load_mat), got {type(recording).__name__}")
    if apM is not None:
        if method == "idim-ls":
            raise DataError("apM (a priori mass) is not used by idim-ls, which needs no initial values; leave it out")
        apM = _checks.real("the a priori mass apM", apM, "kg", lo=0.0)
    if initial is not None:
        if method not in ("oe-nm", "oe-lm"):
            start = "starts from apM" if method == "didim" else "needs no initial values"
            raise DataError(f"initial values are used by the output-error methods (oe-nm, oe-lm); {method} {start}")
        initial = _checks.physical(initial, "initial")
        if offset and "OF" not in initial:
            raise DataError("offset=True but initial has no OF: give its initial value (N), e.g. 0.0")
    _checks.one_of("criterion", criterion, CRITERIA)
    if criterion != "force" and method not in ("oe-nm", "oe-lm"):
        raise DataError(f"criterion={criterion!r} applies to the output-error methods (oe-nm, oe-lm), not to {method}")
    if progress is not None and not callable(progress):
        raise DataError(f"progress must be a function taking a message (or None), got {type(progress).__name__}")
    check_options(model, method, options)
    # before any fit (oe-lm runs the three-step DIDIM first for its start); each method checks it again itself
    supports(structure, method_supports(method, model), method)
    check_sampling(recording, model, method, options)
    _checks.excitation(recording.qr, recording.u_ext, Model(model, offset=offset).param_names())
    if not np.any(recording.force):
        raise DataError(f"{recording.name or 'record'}: the measured force is zero everywhere: nothing to identify "
                        "from (check the force column and its scale, e.g. gtau)")
    from .check import enforce

    chk = enforce(recording, controller_check)
    _warn_findings(recording)
    if method == "idim-ls":
        return _with_check(_with_force_error(recording, idim_ls(recording, structure, **options)), chk)
    if method == "didim":
        fit = didim_rigid if model == "rigid" else didim_flexible
        return _with_check(_with_force_error(recording, fit(recording, apM, model=structure, progress=progress,
                                                            **options)), chk)

    t0 = time.perf_counter()
    pre: Optional[IdentificationResult] = None
    # the simulator the user chose serves the starting runs too
    numerics = {k: options[k] for k in ("substeps", "integrator", "sim_tol") if k in options}
    law = Model(model, offset=offset, coulomb_eps=structure.coulomb_eps, coulomb_law=structure.coulomb_law)
    if initial is None:
        m0 = apM if apM is not None else a_priori_mass(recording)
        if model == "rigid":
            initial = {"M": m0, "Fv": 0.0, "Fc": 0.0, **({"OF": 0.0} if offset else {})}
        elif method == "oe-lm":
            # a local method: start it from the three-step DIDIM estimate, the pseudo-regular values of eq. (33) only
            # when DIDIM did not converge (they can lead it to a local minimum when the load friction is large)
            pre = didim_flexible(recording, apM, model=law, progress=progress, **numerics)
            if pre.converged:
                initial = {**pre.frozen, **pre.params}
            else:
                rigid = pre.steps.get("rigid", pre) if pre.model == "flexible" else pre
                initial = pseudo_regular_initial(rigid.params)
        else:
            pre = didim_rigid(recording, m0, model=replace(law, kind="rigid"), progress=progress, **numerics)
            initial = pseudo_regular_initial(pre.params)
        # extra terms start at 0, like the frictions of eq. (22)
        initial = {**{t.name: 0.0 for t in structure.terms}, **initial}
    solver = oe_nm if method == "oe-nm" else oe_lm
    if method == "oe-nm" and model == "rigid" and any(v == 0 for v in initial.values()):
        # Nelder-Mead scales by the initial values: zero frictions start from a small fraction of the force scale
        initial = {k: (v if v != 0 else 1.0) for k, v in initial.items()}
    r = solver(recording, structure, initial, criterion=criterion, progress=progress, **options)
    if pre is not None:
        r.steps = {"didim" if pre.model == "flexible" and "rigid" in pre.steps else "rigid": pre}
        r.simulations += pre.simulations
    r.elapsed_s = time.perf_counter() - t0
    return _with_check(_with_force_error(recording, r), chk)


def _with_check(r: IdentificationResult, chk) -> IdentificationResult:
    """The result with the controller check it was fitted after (:func:`didim.check.enforce`), None when off."""
    r.options["controller_check"] = None if chk is None else chk.to_dict()
    return r


def _with_force_error(recording: Recording, r: IdentificationResult) -> IdentificationResult:
    """Sets the headline measure: the closed-loop force error of the result's full model on all samples, the same
    number ``didim.simulate(recording, r).relative_error(recording)`` gives (one simulation)."""
    from ._errors import DidimError
    from .simulation import simulate

    def measure(x: IdentificationResult) -> float:
        """Sets x's full-rate force error (and its start's, when it has one); returns the error after the start."""
        if x.structure is None:
            return x.force_error
        try:
            sim = simulate(recording, x)
        except DidimError:
            x.force_error = float("nan")
            return x.force_error
        x.force_error = sim.relative_error(recording)
        band = x.options.get("band_hz")
        if band and band < 0.5 * recording.fs:
            from .signal import lowpass

            y, ys = (lowpass(f, band, recording.fs) for f in (recording.force, sim.force))
            x.force_error_band = float(np.linalg.norm(y - ys) / np.linalg.norm(y))
        k, after = sim.settled(recording)
        if k and np.isfinite(after):
            x.start_s, x.force_error_after_start = k * recording.dt, after
            return after
        return x.force_error

    r.set_axis(recording.axis)
    for step in r.steps.values():  # each step of a multi-step method, measured as the result is
        measure(step)
    if recording.qr_lead.size and r.structure is not None:
        r.notes.append(recording.lead_in_note())
    if recording.controller_origin:
        r.notes.append(f"no controller was described: the {recording.controller_origin}")
    judged = measure(r)  # the error the sanity checks below judge: after a record's start, when it has one
    # one sanity check for every method: a model whose simulated force misses the measured one by more than the force
    # itself explains nothing, whatever the method's own convergence test said
    if r.converged and not (judged <= ABSURD_FORCE_ERROR):
        r.converged = False
        what = (f"its closed-loop force error is {100 * judged:.0f} % (more than "
                f"{100 * ABSURD_FORCE_ERROR:.0f} % means worse than predicting no force at all)"
                if np.isfinite(r.force_error) else "its model cannot be simulated in closed loop (the loop diverges or "
                "the parameters are not physical)")
        r.message = (f"the result explains nothing: {what}; check the units, the controller and the initial values "
                     "(apM)") + (f"; the method said: {r.message}" if r.message else "")
    elif r.converged and judged > POOR_FORCE_ERROR:
        why = (f"the model explains little of the force: its closed-loop force error is {100 * judged:.0f} %; "
               "check that the controller is the one that ran the axis, the force's units and the record")
        r.notes.append(why)
        warnings.warn(f"{recording.name or 'record'}: {why}", DidimWarning, stacklevel=3)
    return r


#: A closed-loop force error above this (relative) is worse than predicting zero force: no fit, whatever converged.
ABSURD_FORCE_ERROR = 1.0
#: Above this a converged fit is kept but flagged (a note and a DidimWarning): the model explains little of the force.
POOR_FORCE_ERROR = 0.5



def simulate(recording: Recording, params, model: Union[str, Model] = "rigid", **options):
    """Simulates the recording's closed loop with ``params``, for every plant: one axis's record with a parameter
    mapping, sequence or result (:func:`didim.simulation.simulate`, whose options it takes), a robot's record with a
    robot's identification result (its robot, model, friction law and parameters; the same closed loop as the
    identification's and ``didim simulate``'s). A robot's :class:`didim.SimResult` holds ``force`` (samples × joints,
    as the record's), ``q``, ``qd``, ``qdd`` the link sides and ``motor`` the motor sides (joints × samples), and
    ``relative_error_per_joint(record)``."""
    from .simulation import simulate as simulate_axis

    from .result import IdentificationResult

    robot_result = isinstance(params, IdentificationResult) and params.robot is not None
    if not (isinstance(recording, Recording) and (recording.has_joint_columns or robot_result)):
        return simulate_axis(recording, params, model, **options)
    name = recording.name or "the record"
    if not robot_result:
        raise DataError(f"{name} is a robot's ({len(recording.joint_names)} joints: {', '.join(recording.joint_names)}): "
                        "simulate it with a robot's identification result (didim.identify(rec, robot, ...) or "
                        "didim.load_result(RESULT.json)), which carries the robot, its model and parameters")
    if not recording.has_joint_columns:
        raise DataError(f"this is a robot's result ({params.robot.ndof} joints of {params.robot.name}) and {name} is one "
                        "axis's: simulate it on a record of that robot (its joints' columns and controllers)")
    given = ([] if isinstance(model, str) and model == "rigid" else ["model"]) + sorted(options)
    if given:
        raise DataError(f"a robot's result carries its model and its simulator: leave {', '.join(given)} out")
    from .methods.robot import simulate_robot
    from .simulation import SimResult

    sim = simulate_robot(recording, params)
    return SimResult(model=params.structure.kind, params=dict(params.params), t=recording.t, force=sim["force"],
                     q=sim["q"].T, qd=sim["qd"].T, qdd=sim["qdd"].T, joints=tuple(recording.joint_names),
                     motor=sim.get("theta", sim["q"]).T)

__all__ = ["identify", "simulate", "METHODS"]


def _warn_findings(recording: Recording) -> None:
    """Each finding of :meth:`Recording.diagnose` (one axis's or each joint's) as a :class:`DidimWarning`."""
    for finding in recording.diagnose():
        warnings.warn(f"{recording.name or 'record'}: {finding}", DidimWarning, stacklevel=3)


def _robot_plant(model, recording) -> bool:
    """Whether a call is a robot's: a :class:`didim.Robot`, a model of one, or a record of joint columns (every entry
    point asks this one question)."""
    from .robots import Robot

    return isinstance(model, Robot) or (isinstance(model, Model) and model.robot is not None) \
        or _has_joint_columns(recording)


def _has_joint_columns(recording) -> bool:
    """A robot's record: a :class:`Recording` whose signals are (samples, joints)."""
    return isinstance(recording, Recording) and recording.has_joint_columns


def _identify_robot(recording, robot, method: str, *, offset, apM, initial, criterion, progress, controller_check,
                    **options):
    """:func:`identify` of a robot's record (a :class:`didim.Recording` with joint columns) with a model of its
    robot (a :class:`didim.Model` with ``robot``, or the :class:`didim.Robot`, whose model fits an offset per joint
    unless ``offset=False``: :func:`didim.model.as_model`): "didim" (from the URDF's values) or "idim-ls";
    ``max_iter`` and ``tol`` go to DIDIM; ``controller_check`` as for one axis, on each joint."""
    from .check import enforce
    from .robots import Robot, didim as robot_didim, idim_ls as robot_idim_ls

    if not _has_joint_columns(recording):
        raise DataError(f"a robot is identified on a robot's record (didim.load_record(path, robot=robot)), got "
                        f"{type(recording).__name__}")
    if not isinstance(robot, Robot) and not (isinstance(robot, Model) and robot.robot is not None):
        raise DataError(f"a robot's record is identified with its didim.Robot (didim.Robot.from_urdf(path)) or a "
                        f"didim.Model of it, got {type(robot).__name__}")
    for name, value, why in (("apM", apM, "starts from the URDF's values"),
                             ("criterion", None if criterion == "force" else criterion, "fits the force")):
        if value is not None:
            raise DataError(f"{name} does not apply to a robot: DIDIM on a robot {why}")
    if initial is not None and not (isinstance(initial, IdentificationResult) and initial.robot is not None):
        raise DataError("a robot's DIDIM starts from the URDF's values, or from a result of the same robot: "
                        f"initial=didim.load_result('r.json') (a robot's result), got {type(initial).__name__}")
    model = as_model(robot, offset=None if offset is None else _checks.flag("offset", offset),
                     elastic=options.pop("elastic", None))
    if model.law is not None:
        raise DataError("a robot's friction law through zero speed is fitted from the record: give its model without "
                        "coulomb_eps")
    robot = model.robot
    if method not in ("didim", "idim-ls", "oe-lm"):
        raise DataError(f"method {method!r} is not available for robots: use 'didim', 'oe-lm' or 'idim-ls'")
    allowed = {"max_iter", "tol", "frozen"} if method == "didim" else {"max_iter", "tol"} if method == "oe-lm" \
        else set()
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise DataError(f"unknown option(s) {', '.join(unknown)} for a robot's {method}; it takes "
                        f"{', '.join(sorted(allowed)) or 'none'}")
    if list(recording.joint_names) != robot.joint_names:
        raise DataError(f"the record's joints ({', '.join(recording.joint_names)}) are not the robot's "
                        f"({', '.join(robot.joint_names)}), in the same order")
    chk = enforce(recording, controller_check)
    _warn_findings(recording)
    if initial is not None and (method == "idim-ls" or initial.robot.joint_names != robot.joint_names):
        raise DataError("initial (a result to start from) is for a robot's didim and oe-lm, with a result of the same "
                        f"robot's joints ({', '.join(robot.joint_names)})")
    if initial is not None:
        # the same chain (a result read from a file has its own copy of the URDF): its parameters by name
        initial = replace(initial, structure=replace(initial.structure, robot=robot))
    if method == "didim":
        res = robot_didim(recording, model, progress=progress, start=initial, **options)
    elif method == "oe-lm":
        from .methods.robot import oe_lm as robot_oe_lm

        res = robot_oe_lm(recording, model, progress=progress, start=initial, **options)
    else:
        res = robot_idim_ls(recording, model)
    if chk is not None:
        res.options["controller_check"] = chk.to_dict()
        res.notes.insert(0, chk.summary())
    from .methods.robot import actuation_notes

    res.notes += actuation_notes(recording, res)
    res.notes[:0] = [f"no controller was described: {o}" for o in recording.controller_origin]
    if recording.lead_in_note():
        res.notes.insert(0, recording.lead_in_note())
    return res
