"""Command line: ``didim identify``, ``didim demo``, ``didim sweep``. User errors exit with status 2 and one line on stderr
(``--debug`` shows the traceback)."""

from __future__ import annotations

import argparse
import math
import sys
from typing import List, Optional

from ._errors import DidimError


def _progress(quiet: bool):
    if quiet:
        return None
    return lambda msg: print(f"  … {msg}", file=sys.stderr, flush=True)


def _load(args, path: str):
    """The record at ``path`` with the command's --controller, --columns and --force-scale."""
    from .formats._io import beside
    from .formats.loaders import load_record, parse_columns

    controller = getattr(args, "controller", None) or None  # a path: load_record reads its "units" too
    if controller is None and not path.lower().endswith(".mat") and beside(path) and not getattr(args, "quiet", False):
        print(f"  … controller from {beside(path)}", file=sys.stderr, flush=True)
    gain = getattr(args, "pulses_gain", "log")
    return load_record(path, controller=controller, columns=parse_columns(getattr(args, "columns", None)),
                       force_scale=getattr(args, "force_scale", 1.0),
                       pulses_gain=gain if gain == "log" else _number_arg("--pulses-gain", gain),
                       lead_in=None if getattr(args, "lead_in", "auto") == "none" else "auto",
                       units=getattr(args, "units", None))


def _number_arg(flag: str, text: str) -> float:
    from ._errors import DataError

    try:
        return float(text)
    except ValueError:
        raise DataError(f"{flag} takes 'log' or a number, got {text!r}") from None


def _record_options(p) -> None:
    """The options every command that reads a record takes."""
    p.add_argument("--controller", metavar="FILE",
                   help="the drive's controller (JSON or TOML: transfer_function, cascade, emps or pd); default: the "
                        "MAT file's EMPS gains, or NAME_controller.json beside a CSV/Parquet/HDF5 record")
    p.add_argument("--columns", metavar="MAP", help="column names of the file, e.g. force=F_motor,qm=encoder "
                   "(didim's names: t, qr, force, qm, ql, u_ext)")
    p.add_argument("--force-scale", type=float, default=1.0, metavar="N_PER_UNIT",
                   help="N per unit of the logged force (e.g. the drive gain for a force logged in V); default 1")
    p.add_argument("--pulses-gain", default="log", metavar="GAIN",
                   help="MAT files with pulses_N: the gain of the pulses in the logged command, 'log' (default: read "
                        "from the log) or a number (1: pulses_N as it is)")
    p.add_argument("--units", default=None, metavar="UNITS",
                   help="what the record's positions and force are logged in: m (default), mm, um, rad, deg, rev, "
                        "counts/rev=N or counts/m=N, with N*m or a drive unit and its scale (e.g. 'deg', 'mm,V=2.5'); "
                        "also read from a CSV header such as qm[deg] or the controller file's \"units\"")
    p.add_argument("--controller-check", choices=("error", "warn", "off"), default="error",
                   help="before any fit the controller's law on the logged qr and qm must give the logged force: "
                        "'error' (default) refuses a controller that does not (exit 2), naming the likely mistake; "
                        "'warn' goes on; 'off' skips the check")
    p.add_argument("--lead-in", choices=("auto", "none"), default="auto",
                   help="a log that begins in the acceleration from rest, the axis lagging the reference: 'auto' "
                        "(default) simulates from the rest its reference left, extrapolated back; 'none' from rest "
                        "on the first reference sample, as the paper")


def _robot_record(args, path: str, robot):
    """A robot's record at ``path`` with the command's --controller (default: NAME_controller.json beside it)."""
    from ._errors import DataError
    from .formats.loaders import load_record

    for flag, value, default in (("--columns", getattr(args, "columns", None), None),
                                 ("--force-scale", getattr(args, "force_scale", 1.0), 1.0)):
        if value != default:
            raise DataError(f"{flag} applies to one axis's record; a robot's record has columns t, qr_1..qr_n, "
                            "force_1..force_n, qm_1..qm_n (or qr_<joint>, ...): rename the file's header to those "
                            "(a drive unit's scale goes in --units, e.g. deg,A=2.5)")
    return load_record(path, robot=robot, controller=getattr(args, "controller", None) or None,
                       units=getattr(args, "units", None),
                       lead_in=None if getattr(args, "lead_in", "auto") == "none" else "auto")


def cmd_identify_robot(args) -> int:
    from ._errors import DataError
    from .formats._io import save_figure, write_text
    from .api import identify
    from .robots import Robot

    for flag, value in (("--model", args.model != "rigid"), ("--variant", args.variant), ("--apm", args.apm),
                        ("--criterion", args.criterion != "force"), ("--set", args.set),
                        ("--pulses-gain", getattr(args, "pulses_gain", "log") != "log")):
        if value:
            why = ("it reads the pulses_N of one axis's MAT file; a robot's known feedforward goes in its record's "
                   "u_ext_1..u_ext_n columns" if flag == "--pulses-gain" else "DIDIM starts from the URDF's values")
            if flag == "--model":
                why += "; a robot's elastic joints are named with --elastic J1,J2 or --elastic all"
            raise DataError(f"{flag} does not apply to a robot (--urdf): {why}")
    _check_outputs([args.file, args.controller, args.urdf], [args.json, args.plot])
    if args.plot:
        _check_figure_format(args.plot)
    robot = Robot.from_urdf(args.urdf, _joints(args))
    if robot.locked_joints and not args.quiet:
        print(f"  … {', '.join(robot.locked_joints)} locked at zero (not actuated); --joints picks others",
              file=sys.stderr, flush=True)
    rec = _robot_record(args, args.file, robot)
    opts = {k: v for k, v in (("max_iter", args.max_iter), ("tol", args.tol)) if v is not None}
    if opts and args.method not in ("didim", "oe-lm"):
        raise DataError("--max-iter and --tol apply to didim and oe-lm")
    model = _robot_model(args, robot)  # the robot's model, carried whole to the fit
    if args.start:
        opts["initial"] = _start_result(args.start)
    res = identify(rec, model, args.method, progress=_progress(args.quiet), controller_check=args.controller_check,
                   **opts)
    print(res.summary())
    if args.json:
        import json

        write_text(args.json, json.dumps(res.to_dict(), indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        from .simulation import plot_robot_forces
        from .methods.robot import simulate_robot

        save_figure(plot_robot_forces(rec, simulate_robot(rec, res)["force"], title=f"{res.method}: {rec.name}"),
                    args.plot, dpi=110)
        print(f"wrote {args.plot}")
    if not res.converged:
        print(f"didim: not converged: {_one_line(res.message)}", file=sys.stderr)
        return 1
    return 0


def cmd_identify(args) -> int:
    from .formats._io import save_figure, write_text
    from .api import identify
    from .plots import plot_fit

    if args.urdf:
        return cmd_identify_robot(args)
    given = [f for f, v in (("--joints", args.joints), ("--elastic", args.elastic), ("--backlash", args.backlash)) if v]
    if given:
        from ._errors import DataError

        raise DataError(f"{given[0]} names a robot's joints: give the robot with --urdf (one axis's two masses are "
                        "--model flexible)")
    if args.start:
        from ._errors import DataError

        raise DataError("--start is a robot's (--urdf) result to start from; one axis starts from --apm")
    _check_outputs([args.file, args.controller], [args.json, args.plot])
    if args.plot:
        _check_figure_format(args.plot)
    rec = _load(args, args.file)
    opts = {}
    if args.apm is not None:
        opts["apM"] = args.apm  # identify refuses it for idim-ls, which needs no initial values
    if args.method in ("oe-nm", "oe-lm", "oe-gn") or args.criterion != "force":
        opts["criterion"] = args.criterion  # identify refuses a position criterion for the other methods
    if args.variant is not None:
        if not (args.method == "didim" and args.model == "flexible"):
            from ._errors import DataError

            raise DataError("--variant chooses the three-step DIDIM's variant: use it with --model flexible --method didim")
        opts["variant"] = args.variant
    if args.max_iter is not None:
        opts["max_iter"] = args.max_iter
    if args.tol is not None:
        opts["tol"] = args.tol
    from .sweep import parse_values

    for k, v in _keyvals(args.set, parse_values).items():
        if k in opts or k in ("offset", "progress", "model", "method"):
            from ._errors import DataError

            raise DataError(f"--set {k}=…: {k} has its own option (see didim identify --help)")
        opts[k] = v[0] if len(v) == 1 else v
    res = identify(rec, args.model, args.method, offset=bool(args.offset), progress=_progress(args.quiet),
                   controller_check=args.controller_check, **opts)
    print(res.summary())
    if args.json:
        write_text(args.json, res.to_json() + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        save_figure(plot_fit(rec, res), args.plot, dpi=110)
        print(f"wrote {args.plot}")
    if not res.converged:
        print(f"didim: not converged: {_one_line(res.message)}", file=sys.stderr)
        return 1
    return 0


def cmd_simulate(args) -> int:
    """Applies a saved result to a record: the closed loop simulated with the result's model against the measured
    force (the paper's cross-test, Fig. 6)."""
    import json

    from .formats._io import save_figure, write_text
    from .result import load_result
    from .simulation import simulate

    _check_outputs([args.file, args.result, args.controller], [args.json, args.plot])
    if args.plot:
        _check_figure_format(args.plot)
    from .check import enforce

    result = load_result(args.result)
    if result.robot is not None:  # a robot's result
        return _simulate_robot(args, result)
    rec = _load(args, args.file)
    chk = enforce(rec, args.controller_check)
    sim = simulate(rec, result)
    err = sim.relative_error(rec)
    st = result.structure
    print(f"{args.file}: closed-loop force error of {args.result} ({result.method}, {st.kind} model): {100 * err:.2f} %")
    if result.force_error == result.force_error:
        print(f"  (on its own record, as fitted: {100 * result.force_error:.2f} %)")
    if rec.qr_lead.size:
        print(f"  ({rec.lead_in_note()})")
    if rec.controller_origin:
        print(f"  (no controller was described: the {rec.controller_origin})")
    if chk is not None:
        print(f"  ({chk.summary()})")
    if args.json:
        write_text(args.json, json.dumps({"record": args.file, "result": args.result, "force_error": err,
                                          "lead_in_s": rec.qr_lead.size * rec.dt,
                                          "model": st.to_dict(), "params": result.all_params,
                                          "controller_check": None if chk is None else chk.to_dict()},
                                         indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        save_figure(sim.plot(rec), args.plot, dpi=110)
        print(f"wrote {args.plot}")
    from .api import ABSURD_FORCE_ERROR

    if not err <= ABSURD_FORCE_ERROR:
        print(f"didim: no fit: the result does not describe {args.file}: its simulated force misses the measured "
              f"one by {100 * err:.0f} % (more than {100 * ABSURD_FORCE_ERROR:.0f} % is worse than predicting no force); "
              "check that the record, its controller and the result belong to the same axis and units", file=sys.stderr)
        return 1
    return 0


def _simulate_robot(args, result) -> int:
    """``didim simulate`` of a robot's result: its closed loop on the record, the force error over all joints and per
    joint."""
    import json

    from .formats._io import save_figure, write_text
    from .check import enforce
    from .api import simulate
    from .methods.robot import deflection_errors

    rec = _robot_record(args, args.file, result.robot)
    chk = enforce(rec, args.controller_check)
    sim = simulate(rec, result)
    err, per = sim.relative_error(rec), sim.relative_error_per_joint(rec)
    deflection = deflection_errors(rec, {"q": sim.q.T, "theta": sim.motor.T}, result.structure)
    print(f"{args.file}: closed-loop force error of {args.result} ({result.method}, {rec.ndof}-joint robot "
          f"{result.robot.name}): {100 * err:.2f} %")
    for j, e in per.items():
        print(f"  {j}: {100 * e:.2f} %" + (f"; link-minus-motor deflection error {100 * deflection[j]:.1f} % RMS "
                                          "(against ql − qm)" if j in deflection else ""))
    if result.structure.elastic and not deflection:
        print("  (no link-minus-motor deflection error: the record holds no link-side positions of the elastic joints, "
              "ql_1..ql_n or ql_<joint> columns)")
    if chk is not None:
        print(f"  ({chk.summary()})")
    for o in rec.controller_origin:
        print(f"  (no controller was described: {o})")
    if args.json:
        write_text(args.json, json.dumps({"record": args.file, "result": args.result, "force_error": err,
                                          "force_error_per_joint": per, "deflection_error_per_joint": deflection,
                                          "params": result.params,
                                          "controller_origin": list(rec.controller_origin),
                                          "controller_check": None if chk is None else chk.to_dict()},
                                         indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        from .simulation import plot_robot_forces

        save_figure(plot_robot_forces(rec, sim.force, title=f"{args.result} on {rec.name}"), args.plot, dpi=110)
        print(f"wrote {args.plot}")
    return 0


def cmd_payload(args) -> int:
    """The payload on a robot's last link from a record made with it, the robot's parameters from a saved result."""
    import json

    from ._errors import DataError
    from .formats._io import write_text
    from .result import load_result
    from .robots import payload

    _check_outputs([args.file, args.result, args.controller], [args.json])
    result = load_result(args.result)
    if result.robot is None:
        raise DataError(f"{args.result}: not a robot's result (didim identify --urdf ... --json OUT.json)")
    from .check import enforce

    rec = _robot_record(args, args.file, result.robot)
    enforce(rec, args.controller_check)
    p = payload(rec, result, progress=_progress(args.quiet))
    print(p.summary())
    if args.json:
        write_text(args.json, json.dumps(p.to_dict(), indent=2) + "\n")
        print(f"wrote {args.json}")
    if not p.converged:
        print("didim: the payload fit did not converge", file=sys.stderr)
        return 1
    return 0


def _check_outputs(inputs, outputs) -> None:
    """Fails before any work when an output cannot be written, is an input or another output (see _io.check_outputs)."""
    from .formats._io import check_outputs

    check_outputs([inputs] if isinstance(inputs, str) else inputs, outputs)


def _check_figure_format(path: str) -> None:
    import os

    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ._errors import DataError

    ext = os.path.splitext(path)[1].lstrip(".").lower() or "png"
    formats = FigureCanvasAgg(Figure()).get_supported_filetypes()
    if ext not in formats:
        raise DataError(f"cannot write a figure as .{ext} ({path}): use one of {', '.join('.' + f for f in sorted(formats))}")


def _one_line(msg: str) -> str:
    return " ".join(str(msg).split())


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"didim: warning: {_one_line(str(message))}", file=sys.stderr, flush=True)


def cmd_controller_fit(args) -> int:
    """Fits the controller of a record from its log and writes it as a controller file."""
    import json

    from .formats._io import write_text
    from .controller_fit import fit_controller

    _check_outputs([args.file], [args.json])
    if args.urdf:  # a robot's record: each joint's law from its own log, written as a joints file
        from .formats.loaders import load_record
        from .robots import Robot

        if args.columns or args.force_scale != 1.0:
            from ._errors import DataError

            raise DataError("--columns and --force-scale apply to one axis's record; a robot's drive unit goes in "
                            "--units (e.g. deg,A=2.5)")
        robot = Robot.from_urdf(args.urdf, _joints(args))
        rec = load_record(args.file, robot=robot, controller=None, units=args.units, beside_controller=False)
        for line in rec.controller_origin:
            print(f"{args.file}: {line}")
        if args.json:  # in the record's own units, which the file declares, so that --controller reads it back
            from .controllers import in_units

            entries = []
            for j, c in enumerate(rec.controllers):
                u = rec.units[j] if rec.units else None
                if u is None or u.is_si:
                    entries.append(c.transfer_function(rec.dt).to_dict())
                else:
                    native = in_units(c, rec.dt, 1 / u.position_factor, 1 / u.force_factor)
                    entries.append({**native.transfer_function(rec.dt).to_dict(), "units": u.to_dict()})
            spec = {"type": "joints", "joints": entries}
            write_text(args.json, json.dumps(spec, indent=1) + "\n")
            print(f"wrote {args.json}")
        return 0
    if args.joints:
        from ._errors import DataError

        raise DataError("--joints picks a URDF's joints: give --urdf too")
    rec = _load_plain(args, args.file)
    cf = fit_controller(rec)
    print(f"{args.file}: {cf.summary()}")
    if args.json:
        spec = cf.to_dict()
        if not rec.units.is_si:  # in the record's own units, which the file declares: --controller reads it back
            from .controllers import in_units

            native = in_units(cf.controller, rec.dt, 1 / rec.units.position_factor, 1 / rec.units.force_factor)
            spec = {**native.transfer_function(rec.dt).to_dict(), "units": rec.units.to_dict(), "note": spec["note"]}
        write_text(args.json, json.dumps(spec, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


def cmd_controller_check(args) -> int:
    """Checks the record's described controller against its log."""
    from .check import enforce

    rec = _checked_record(args, args.file)
    chk = enforce(rec, "warn" if args.controller_check == "off" else args.controller_check)
    print(f"{args.file}: {chk.summary()}")
    return 0 if chk.passed else 2


def _checked_record(args, path: str):
    """The record of ``didim controller check``: a robot's with --urdf or a joints controller file, else one axis's."""
    from ._errors import DataError
    from .controllers import _spec
    from .robots import Robot

    if getattr(args, "urdf", None):
        return _robot_record(args, path, Robot.from_urdf(args.urdf, _joints(args)))
    if args.joints:
        raise DataError("--joints picks a URDF's joints: give --urdf too")
    if args.controller:
        _, spec = _spec(args.controller)
        if isinstance(spec, dict) and spec.get("type") == "joints" and isinstance(spec.get("joints"), list):
            return _robot_record(args, path, _NumberedJoints(len(spec["joints"])))
    return _load(args, path)


class _NumberedJoints:
    """A robot's joints known only by number (a joints controller file without a URDF): 1..n, their kinds unknown
    (revolute is assumed: the controller check does not depend on it)."""

    def __init__(self, n: int):
        self.joint_names = [str(i + 1) for i in range(n)]
        self.joint_kinds = ["revolute"] * n


def _load_plain(args, path: str):
    """A record whose controller is fitted from its own log (no --controller): its signals, in SI."""
    from .formats.loaders import load_record, parse_columns

    return load_record(path, controller=None, columns=parse_columns(getattr(args, "columns", None)),
                       force_scale=getattr(args, "force_scale", 1.0), units=getattr(args, "units", None),
                       beside_controller=False)


def cmd_demo(args) -> int:
    from .formats._io import write_text
    from .demo import demo_report, run_demo, run_rest_case

    _check_outputs([], [args.json])
    results = run_demo(seed=args.seed, progress=_progress(args.quiet))
    rest = run_rest_case(seed=args.seed, progress=_progress(args.quiet))
    print(demo_report(results, rest))
    if args.json:
        import json

        write_text(args.json, json.dumps({k: r.to_dict() for k, r in {**results, **rest}.items()}, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


def cmd_doctor(args) -> int:
    from .formats._io import write_text
    from .doctor import doctor

    _check_outputs([args.file, args.validate, args.controller, args.urdf, args.start], [args.json, args.html,
                                                                                         args.result])
    if args.start and not args.urdf:
        from ._errors import DataError

        raise DataError("--start is a robot's (--urdf) result to start from; one axis's doctor starts from --apm")
    if args.urdf:
        d = _robot_diagnosis(args)
    else:
        given = [f for f, v in (("--joints", args.joints), ("--elastic", args.elastic), ("--backlash", args.backlash))
                 if v]
        if given:
            from ._errors import DataError

            raise DataError(f"{given[0]} names a URDF's joints: give --urdf too (one axis's two masses are --model "
                            "flexible)")
        rec = _load(args, args.file)
        val = _load(args, args.validate) if args.validate else None
        from .doctor import BaseFitError

        try:
            d = doctor(rec, args.model, val, apM=args.apm, alpha=args.alpha, progress=_progress(args.quiet),
                       controller_check=args.controller_check)
        except BaseFitError as e:  # not bad input: the record does not support the base model (like a fit not
            # converged)
            print(f"didim: doctor: {_one_line(str(e))}", file=sys.stderr)
            return 1
    print(d.summary())
    if args.json:
        write_text(args.json, d.to_json() + "\n")
        print(f"wrote {args.json}")
    if args.html:
        write_text(args.html, d.to_html())
        print(f"wrote {args.html}")
    if args.result:
        d.final_result.save(args.result)
        print(f"wrote {args.result} (the final model: didim simulate RECORD {args.result})")
    return 0


def _start_result(path: str):
    """--start: a robot's saved result (``didim identify ... --json``, or one written from published values) that
    DIDIM starts from instead of the URDF's values."""
    from ._errors import DataError
    from .result import load_result

    res = load_result(path)
    if res.robot is None:
        raise DataError(f"{path}: --start takes a robot's result (didim identify REC --urdf U --json OUT), this one is "
                        "a single axis's")
    return res


def _robot_diagnosis(args):
    """``didim doctor REC --urdf U``: the robot's base fit, where each joint's simulation and record differ, and the
    physics each joint misses (:func:`didim.doctor.robot.doctor_robot`)."""
    from ._errors import DataError
    from .doctor import doctor
    from .robots import Robot

    for flag, value in (("--model", args.model != "rigid"), ("--apm", args.apm is not None)):
        if value:
            raise DataError(f"{flag} does not apply to a robot (--urdf): DIDIM starts from the URDF's values")
    if args.hold_bodies and not args.start:
        raise DataError("--hold-bodies holds the bodies of the --start result: give --start RESULT.json too, a "
                        "result of this robot whose bodies you trust (published values, or the CAD's: didim "
                        "identify ... --json)")
    robot = Robot.from_urdf(args.urdf, _joints(args))
    rec = _robot_record(args, args.file, robot)
    val = _robot_record(args, args.validate, robot) if args.validate else None
    start = _start_result(args.start) if args.start else None
    # the bodies' base parameters of the start held in every fit: what the free bodies would take (a spring on a
    # joint whose angle to gravity is its own) is left to the candidates
    frozen = {b: start.params[b] for b in start.base.bodies_only} if args.hold_bodies else None
    return doctor(rec, _robot_model(args, robot), val, alpha=args.alpha, progress=_progress(args.quiet),
                  controller_check=args.controller_check, initial=start, frozen=frozen)


def _robot_model(args, robot):
    """The robot's model of the command line: its offset (--offset), elastic joints (--elastic) and their backlash
    (--backlash J=WIDTH,...: each dead zone's total width in the joint's units, rad or m, from which DIDIM estimates it)."""
    from ._errors import DataError
    from .model import as_model

    elastic = [x.strip() for x in args.elastic.split(",")] if getattr(args, "elastic", None) else None
    if elastic == ["all"]:
        elastic = list(robot.joint_names)
    gaps = None
    if getattr(args, "backlash", None):
        gaps = {}
        for item in args.backlash.split(","):
            name, eq, value = item.partition("=")
            if name.strip() in gaps:
                raise DataError(f"--backlash names {name.strip()} twice: give each joint's width once")
            try:
                gaps[name.strip()] = float(value)
            except ValueError:
                eq = ""
            if not eq:
                raise DataError(f"--backlash takes JOINT=WIDTH pairs (the dead zone's total width, rad or m), got "
                                f"{item!r}")
        if not elastic:
            raise DataError("--backlash is a dead zone between an elastic joint's rotor and its link: name the joints "
                            "with --elastic too")
    return as_model(robot, offset=getattr(args, "offset", None), elastic=elastic, backlash_gap=gaps)


def _joints(args):
    """The --joints list (a URDF's actuated joints), None when not given."""
    return [j.strip() for j in args.joints.split(",") if j.strip()] if getattr(args, "joints", None) else None


def _keyvals(items, parse) -> dict:
    from ._errors import DataError

    out = {}
    for item in items or []:
        if "=" not in item:
            raise DataError(f"expected KEY=VALUE, got {item!r}")
        k, v = item.split("=", 1)
        out[k.strip()] = parse(v.strip())
    return out


def cmd_sweep(args) -> int:
    from ._errors import DataError
    from .formats._io import save_figure, write_text
    from .sweep import grid_points, parse_values, random_points, sweep

    _check_outputs([args.record, args.controller], [args.json, args.plot])
    fixed = {k: (v[0] if len(v) == 1 else v) for k, v in _keyvals(args.set, parse_values).items()}
    if args.controller:
        from .controllers import load_controller

        load_controller(args.controller)  # a bad file fails here, once, with its reason
        fixed["controller"] = args.controller
    if args.record:
        from .formats._io import check_input

        fixed["record"] = check_input(args.record, "record (CSV, Parquet, HDF5 or MAT file)")
    elif args.scenario:
        fixed["scenario"] = args.scenario
    else:
        raise DataError("give a record file or --scenario (see didim.sweep.SCENARIOS)")
    fixed.setdefault("model", args.model)
    fixed.setdefault("method", args.method)
    if args.offset:
        fixed["offset"] = True
    grid = _keyvals(args.grid, parse_values)
    if args.seeds:
        grid["seed"] = list(range(args.seeds))
    if args.draws:
        ranges = {}
        for k, v in _keyvals(args.draw, str).items():
            parts = v.split(":")
            try:
                if len(parts) not in (2, 3):
                    raise ValueError
                ranges[k] = (float(parts[0]), float(parts[1])) + ((parts[2],) if len(parts) > 2 else ())
            except ValueError:
                raise DataError(f"--draw {k}={v}: expected KEY=LO:HI[:log|:int] with numbers LO and HI") from None
        points = [dict(p, **g) for g in (grid_points(grid) if grid else [{}])
                  for p in random_points(ranges, args.draws, seed=args.draw_seed, fixed=fixed)]
    else:
        if not grid:
            raise DataError("nothing to sweep: give --grid KEY=VALUES, --seeds N or --draws N with --draw")
        points = grid_points(grid, fixed)
    from .sweep import check_points

    check_points(points)
    if not (math.isfinite(args.agree_rtol) and args.agree_rtol > 0):
        raise DataError(f"--agree-rtol must be a finite fraction > 0, got {args.agree_rtol}")
    if args.workers is not None and args.workers < 1:
        raise DataError(f"--workers must be at least 1, got {args.workers}")
    if args.step is not None and fixed.get("model") != "flexible":
        raise DataError(f"--step {args.step} is a step of the three-step DIDIM: use it with --model flexible")
    executor = None
    if args.dask:
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise DataError("--dask needs the optional extra: pip install 'didim[dask]'") from None
        executor = Client(LocalCluster(n_workers=args.workers or None, threads_per_worker=1)) if args.dask == "local" \
            else Client(args.dask)
    res = sweep(points, workers=args.workers, executor=executor, progress=not args.quiet, agree_rtol=args.agree_rtol)
    res.meta["title"] = args.title or f"{fixed.get('method')} {fixed.get('model')} on {args.record or args.scenario}"
    print(res.summary(args.step))
    if args.json:
        write_text(args.json, res.to_json() + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        save_figure(res.plot(args.step), args.plot, dpi=110)
        print(f"wrote {args.plot}")
    if not any(res.converged(args.step)):
        print(f"didim: not converged: none of the {len(res.results)} runs converged (reasons above)", file=sys.stderr)
        return 1
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with the CLI's one-line user errors: ``didim: error: …`` and exit 2, the usage left to --help. Flags
    are taken whole (no abbreviations: ``--valid`` is not ``--validate``, and stays an error if a flag is added)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # type: ignore[override]
        prog, hint = self.prog, ""
        if message.startswith("unrecognized arguments") and self._subparsers is not None:
            # the top parser reports a subcommand's unknown flags: name that subcommand's help, and the flags meant
            import difflib

            for action in self._subparsers._group_actions:
                cmd = next((a for a in sys.argv[1:] if a in getattr(action, "choices", {}) or {}), None)
                if cmd is None:
                    continue
                sub = action.choices[cmd]
                prog = sub.prog
                known = [o for a in sub._actions for o in a.option_strings]
                meant = [m for t in message.split(":", 1)[1].split() if t.startswith("--")
                         for m in difflib.get_close_matches(t.split("=")[0], known, n=1, cutoff=0.75)]
                if meant:
                    hint = f"; did you mean {', '.join(meant)}?"
        where = prog.partition(" ")[2]  # the subcommand, if any
        print(f"didim: error: {where + ': ' if where else ''}{message}{hint} (see {prog} --help)", file=sys.stderr)
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="didim", description="Identify position-controlled drives from the motor force (DIDIM).")
    p.add_argument("--debug", action="store_true", help="show tracebacks of errors")
    sub = p.add_subparsers(dest="command", required=True)

    i = sub.add_parser("identify", help="identify the dynamic parameters of a recording (CSV, Parquet, HDF5, EMPS MAT)")
    i.add_argument("file", help="the record: CSV, Parquet or HDF5 (columns t, qr, force, qm; optional ql, u_ext) or a "
                   "MAT file in the EMPS layout (t, qm, qg, vir, gtau, kp, kv; optional pulses_N, ql)")
    _record_options(i)
    i.add_argument("--model", choices=["rigid", "flexible"], default="rigid", help="default: rigid")
    i.add_argument("--method", choices=["idim-ls", "didim", "oe-nm", "oe-lm", "oe-gn"], default="didim",
                   help="default: didim (oe-gn is another name of oe-lm)")
    i.add_argument("--variant", choices=["auto", "paper", "friction-split"],
                   help="three-step DIDIM (flexible): the paper's procedure, the friction split (beyond the paper), "
                        "or auto (default: the split when it explains the record clearly better)")
    i.add_argument("--offset", action="store_true", default=None,
                   help="add a constant force OF (N); a robot (--urdf) has one per joint by default")
    i.add_argument("--no-offset", dest="offset", action="store_false",
                   help="a robot (--urdf): no constant torque per joint")
    i.add_argument("--apm", type=float, default=None, help="a priori total mass (kg) to start from")
    i.add_argument("--criterion", choices=["force", "position"], default="force", help="output-error criterion (eq. (32))")
    i.add_argument("--max-iter", type=int, default=None, help="iteration limit of didim, oe-nm and oe-lm")
    i.add_argument("--tol", type=float, default=None, help="stopping tolerance of didim (eq. (21)) and oe-lm")
    i.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="another option of the method, e.g. cutoff_hz=2 or substeps=20 (the Python function's keywords)")
    i.add_argument("--urdf", metavar="URDF", help="a robot: its URDF (the record then has columns t, qr_1..qr_n, "
                   "force_1..force_n, qm_1..qm_n in the URDF's joint order, and --controller a {\"type\": \"joints\"} "
                   "file); --method didim, oe-lm or idim-ls")
    i.add_argument("--joints", metavar="NAMES", help="with --urdf: the actuated joints, comma-separated (default: all "
                   "revolute and prismatic joints of the chain)")
    i.add_argument("--elastic", metavar="J1,J2|all", help="with --urdf: the joints whose transmission is elastic (a "
                   "spring K and damping D between rotor and link), by name or number, or all; --method didim runs "
                   "the three-step DIDIM, --method oe-lm output error from there")
    i.add_argument("--backlash", metavar="J=WIDTH,..", help="with --elastic: a dead zone between an elastic joint's "
                   "rotor and its link, its total width (rad or m) to start from; the three steps fit it (start below it)")
    i.add_argument("--start", metavar="RESULT.json", help="with --urdf: a result of the same robot (a saved "
                   "identification, or published values) that didim and oe-lm start from instead of the URDF's values")
    i.add_argument("--json", metavar="OUT", help="write the result as JSON")
    i.add_argument("--plot", metavar="PNG", help="write measured vs simulated force and the iterations")
    i.add_argument("--quiet", action="store_true", help="no progress messages")
    i.set_defaults(func=cmd_identify)

    o = sub.add_parser("doctor", help="find what physics the model misses, model it and show the fit improve")
    o.add_argument("file", help="the record (CSV, Parquet, HDF5 or EMPS MAT file)")
    _record_options(o)
    o.add_argument("--validate", metavar="FILE", help="a recording the fit does not see (default for one axis: the "
                   "last 30 %% of FILE; a robot's record (--urdf) needs one: without it the mismatch is located, and "
                   "no effect named)")
    o.add_argument("--model", choices=["rigid", "flexible"], default="rigid", help="the base model (default: rigid)")
    o.add_argument("--apm", type=float, default=None, help="a priori total mass (kg)")
    o.add_argument("--alpha", type=float, default=0.01, help="family-wise test level (default 0.01)")
    o.add_argument("--json", metavar="OUT", help="write the diagnosis as JSON: findings (effect, joint, parameters, "
                   "evidence), rejected, ambiguities, rounds, the base and final results")
    o.add_argument("--html", metavar="OUT", help="the report an engineer reads (plots embedded)")
    o.add_argument("--result", metavar="OUT.json", help="the final model as a result (for didim simulate)")
    o.add_argument("--quiet", action="store_true", help="no progress messages")
    o.add_argument("--urdf", metavar="URDF", help="a robot's record: its URDF; the base model is fitted by DIDIM and "
                   "each joint's mismatch located")
    o.add_argument("--joints", metavar="J1,J2,..", help="with --urdf: the actuated joints, as for identify")
    o.add_argument("--elastic", metavar="J1,J2|all", help="with --urdf: the base model's elastic joints, as for "
                   "identify (the doctor then looks for backlash on them too)")
    o.add_argument("--backlash", metavar="J=WIDTH,..", help="with --elastic: the base model's dead zones (each joint's "
                   "total width, rad or m), as for identify")
    o.add_argument("--start", metavar="RESULT.json", help="with --urdf: a result of the same robot (didim identify "
                   "--json, or published values) the base fit starts from instead of the URDF's values")
    o.add_argument("--hold-bodies", action="store_true", help="with --start: the bodies' parameters held at the "
                   "start's in every fit (the drives and the effects fitted): a spring or counterbalance on a joint "
                   "whose angle to gravity is its own, which free bodies take, can then be named")
    o.set_defaults(func=cmd_doctor)

    m = sub.add_parser("simulate", help="apply a saved result to a record: simulated vs measured force (cross-test)")
    m.add_argument("file", help="the record (CSV, Parquet, HDF5 or EMPS MAT file)")
    _record_options(m)
    m.add_argument("result", help="a result saved as JSON (didim identify --json, result.save)")
    m.add_argument("--json", metavar="OUT", help="write the force error, the model and its parameters")
    m.add_argument("--plot", metavar="PNG", help="measured and simulated force and their difference")
    m.add_argument("--quiet", action="store_true", help="no progress messages")
    m.set_defaults(func=cmd_simulate)

    y = sub.add_parser("payload", help="a robot's payload on its last link (mass, centre of mass) from a record made "
                                       "with it, the robot's parameters from a saved result")
    y.add_argument("file", help="the record with the payload (CSV, Parquet or HDF5: t, qr_1.., force_1.., qm_1..)")
    y.add_argument("result", help="the robot's result without the payload (didim identify --urdf ... --json)")
    y.add_argument("--controller", metavar="FILE", help="the joints' controllers ({\"type\": \"joints\", ...}); "
                   "default: NAME_controller.json beside the record")
    y.add_argument("--json", metavar="OUT", help="write mass, mass_sigma, com, com_sigma and the fit")
    y.add_argument("--controller-check", choices=("error", "warn", "off"), default="error",
                   help="each joint's controller against its log before the fit, as for identify")
    y.add_argument("--quiet", action="store_true", help="no progress messages")
    y.set_defaults(func=cmd_payload)

    c = sub.add_parser("controller", help="the drive's controller from the log: fit the linear law u = C_r·qr − C_y·qm, "
                                          "or check a described one against the log")
    csub = c.add_subparsers(dest="action", required=True)
    cf = csub.add_parser("fit", help="fit the controller from a record's qr, qm and force (no controller needed)")
    cf.add_argument("file", help="the record (CSV, Parquet, HDF5)")
    cf.add_argument("--columns", metavar="MAP", help="column names of the file, e.g. force=F_motor,qm=encoder")
    cf.add_argument("--force-scale", type=float, default=1.0, metavar="N_PER_UNIT")
    cf.add_argument("--units", default=None, metavar="UNITS", help="as for identify")
    cf.add_argument("--json", metavar="OUT", help="write the fitted controller as a controller file "
                                                 "(type transfer_function, or joints with --urdf; --controller reads "
                                                 "it back)")
    cf.add_argument("--urdf", metavar="URDF", help="a robot's record: each joint's controller fitted from its log")
    cf.add_argument("--joints", metavar="J1,J2,..", help="with --urdf: the actuated joints, as for identify")
    cf.add_argument("--quiet", action="store_true", help="no progress messages")
    cf.set_defaults(func=cmd_controller_fit)
    cc = csub.add_parser("check", help="check a described controller against the log (exit 2 when it fails)")
    cc.add_argument("file", help="the record")
    _record_options(cc)
    cc.add_argument("--urdf", metavar="URDF", help="a robot's record: its URDF (joint names and kinds); without it a "
                    "joints controller file ({\"type\": \"joints\"}) reads columns qr_1..qr_n, force_1.., qm_1..")
    cc.add_argument("--joints", metavar="J1,J2,..", help="with --urdf: the actuated joints, as for identify")
    cc.add_argument("--quiet", action="store_true")
    cc.set_defaults(func=cmd_controller_check)

    d = sub.add_parser("demo", help="simulated flexible EMPS with known truth: IDIM-LS, three-step DIDIM, exact-sensitivity OE")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--json", metavar="OUT")
    d.add_argument("--quiet", action="store_true")
    d.set_defaults(func=cmd_demo)

    w = sub.add_parser("sweep", help="re-run an identification over a grid or random draws of initial values and noise "
                                     "seeds, in parallel; convergence rate, spread against σ, plot")
    w.add_argument("record", nargs="?", help="record to identify: CSV, Parquet, HDF5 or EMPS MAT file (else --scenario)")
    w.add_argument("--controller", metavar="FILE", help="the drive's controller file (JSON or TOML), as for identify")
    w.add_argument("--scenario", help="simulated record with known truth: flexible-motor-friction, flexible-table3, "
                                      "rigid-emps")
    w.add_argument("--model", choices=["rigid", "flexible"], default="flexible")
    w.add_argument("--method", choices=["idim-ls", "didim", "oe-nm", "oe-lm", "oe-gn"], default="didim")
    w.add_argument("--offset", action="store_true")
    w.add_argument("--grid", action="append", metavar="KEY=VALUES",
                   help="swept values: a,b,c or start:stop:count[:log] (e.g. apM=25:1000:12:log, lambda0=0.25:0.95:8)")
    w.add_argument("--seeds", type=int, default=0, help="noise seeds 0..N-1 (simulated records)")
    w.add_argument("--draws", type=int, default=0, help="random draws instead of (or times) the grid")
    w.add_argument("--draw", action="append", metavar="KEY=LO:HI[:log]", help="range of a random draw")
    w.add_argument("--draw-seed", type=int, default=0)
    w.add_argument("--set", action="append", metavar="KEY=VALUE", help="fixed option of every run (e.g. apM=78)")
    w.add_argument("--workers", type=int, default=None, help="parallel workers (default: all cores)")
    w.add_argument("--dask", metavar="ADDRESS", help="run on a Dask cluster ('local' starts one); needs didim[dask]")
    w.add_argument("--step", choices=["rigid", "mode"], default=None,
                   help="report a step of the three-step DIDIM instead of its result")
    w.add_argument("--agree-rtol", type=float, default=0.01, help="distance to the consensus counted as agreeing")
    w.add_argument("--title", default=None)
    w.add_argument("--json", metavar="OUT")
    w.add_argument("--plot", metavar="PNG")
    w.add_argument("--quiet", action="store_true")
    w.set_defaults(func=cmd_sweep)
    return p


def main(argv: Optional[List[str]] = None, *, _last: bool = False) -> int:
    """Runs the command line; returns 0 on success, 1 when a method did not converge, 2 for a user error (bad file,
    option or parameter, a diverging simulation, nothing identifiable), 130 when interrupted (Ctrl-C), 143 on
    SIGTERM; an interrupted command leaves no temporary file and no half-written output. (``_last``: the process
    exits right after, so SIGINT and SIGTERM are ignored once the command has finished instead of killing the
    interpreter's teardown.)"""
    import warnings

    parser = build_parser()
    args = parser.parse_args(argv)
    received: List[str] = []  # the signals that arrived, even if Python swallowed their exception
    previous = _signals_as_exceptions(received)
    unraisable = sys.unraisablehook

    def quiet_unraisable(u):  # a KeyboardInterrupt raised inside a finaliser (GC, weakref callback) is only reported
        if u.exc_type is not None and issubclass(u.exc_type, KeyboardInterrupt):
            return  # ... by Python: ``received`` keeps it, and the end of main acts on it
        if received:  # after an interrupt: the finaliser of an object it cut short in its construction (e.g. an
            return  # import interrupted half-way, seen with pyparsing under matplotlib): noise, not a fault
        unraisable(u)

    sys.unraisablehook = quiet_unraisable
    with warnings.catch_warnings():
        if not args.debug:
            warnings.showwarning = _show_warning  # one line per warning; restored by catch_warnings
        try:
            code = int(args.func(args))
            if received:  # the interrupt was swallowed where Python cannot raise it: the run went on to its end
                sig = received[0]
                print(f"didim: {'terminated (SIGTERM)' if sig == 'TERM' else 'interrupted'} as the run finished; its "
                      "outputs are complete", file=sys.stderr)
                return 143 if sig == "TERM" else 130
            return code
        except (DidimError, OSError) as e:
            if received and not args.debug:  # an error the interrupt caused (see below)
                return _interrupted(received[0])
            if args.debug:  # the traceback, then the same error line and exit status as without --debug
                import traceback

                traceback.print_exc()
            print(f"didim: error: {_one_line(_describe_error(e))}", file=sys.stderr)
            return 2
        except Terminated:
            return _interrupted("TERM")
        except KeyboardInterrupt:
            return _interrupted("INT")
        except Exception:
            # after a signal, whatever surfaces is its consequence: a library that caught the interrupt half-way
            # and failed on the state it left (matplotlib's renderer: "Invalid bounding box") is still an interrupt
            if not received or args.debug:
                raise
            return _interrupted(received[0])
        finally:
            if not (_last and received):  # an interrupted command exits next: its teardown stays quiet too
                sys.unraisablehook = unraisable
            if previous is not None:
                import signal

                if _last:  # the command is over (done, or cleaned up): nothing is left to interrupt
                    signal.signal(signal.SIGINT, signal.SIG_IGN)
                    signal.signal(signal.SIGTERM, signal.SIG_IGN)
                else:
                    signal.signal(signal.SIGINT, previous[0])
                    signal.signal(signal.SIGTERM, previous[1])


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C so that every ``finally`` runs: temporary files are removed,
    worker processes stopped, and no output is half-written."""


def _interrupted(sig: str) -> int:
    """Says that the run was interrupted (``"INT"``) or terminated (``"TERM"``) and returns its exit status."""
    print(f"didim: {'terminated (SIGTERM)' if sig == 'TERM' else 'interrupted'}; outputs left as they were",
          file=sys.stderr)
    return 143 if sig == "TERM" else 130


def _signals_as_exceptions(received: List[str]):
    """Installs handlers raising KeyboardInterrupt (SIGINT) and :class:`Terminated` (SIGTERM) that also note the
    signal in ``received``; returns the previous handlers (None when signals cannot be set here, e.g. outside the
    main thread)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def on_int(signum, frame):
        received.append("INT")
        raise KeyboardInterrupt()

    def on_term(signum, frame):
        received.append("TERM")
        raise Terminated()

    # a SIGINT ignored from the start (a job a shell runs in the background) stays ignored, as Python leaves it
    keep = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    return (signal.getsignal(signal.SIGINT) if keep else signal.signal(signal.SIGINT, on_int)), \
        signal.signal(signal.SIGTERM, on_term)


def _describe_error(e: BaseException) -> str:
    if isinstance(e, OSError) and not isinstance(e, DidimError) and e.strerror:
        return f"{e.filename}: {e.strerror}" if e.filename else e.strerror
    return str(e)


def _keep_freed_memory() -> None:
    """glibc's allocator, told to keep what the process frees for its next allocations: the simulations' columns
    (25 000 samples, 200 kB each, hundreds of times) otherwise go back to the system at each free and come back as
    fresh pages, zeroed by the kernel (the EMPS doctor: 0.2 s of system time, 0.1 s with this; its peak memory +7 MB).
    The console script's process only; elsewhere (another C library) nothing is done."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_top_pad, m_mmap_threshold = -1, -2, -3
    mallopt(m_mmap_threshold, 32 << 20)  # glibc's largest: blocks up to 32 MB from the heap, not mmap'd one by one
    mallopt(m_trim_threshold, 256 << 20)  # the heap's free top returned only beyond 256 MB
    mallopt(m_top_pad, 16 << 20)  # the heap grows 16 MB at a time


def entry() -> None:
    """The console script: :func:`main`, then exit with its code. After Ctrl-C or SIGTERM (outputs already cleaned up
    as the interruption unwound) the process exits at once, without waiting for core threads still computing."""
    if sys.platform.startswith("linux"):
        _keep_freed_memory()
    try:
        code = main(_last=True)
    except KeyboardInterrupt as e:  # a signal in the instants between main's own handlers and its end
        code = 143 if isinstance(e, Terminated) else 130
    if code in (130, 143):
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    # the interpreter's last collection walks every object the imports made (SciPy's are most of them), 60 ms of a
    # 3 s doctor run: frozen, they are left to the process's end (the outputs are written and closed by now)
    import gc

    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
