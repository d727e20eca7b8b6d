"""One entry point for every identification method."""

from __future__ import annotations

import time
from typing import Dict, Optional

from ._errors import DataError
from .identification import Progress, didim_flexible, didim_rigid, idim_ls, reference_mass
from .output_error import oe_gn, oe_nm, pseudo_regular_initial
from .recording import Recording
from .result import IdentificationResult
from .simulation import MODELS

METHODS = ("idim-ls", "didim", "oe-nm", "oe-gn")


def identify(
    recording: Recording,
    model: str = "rigid",
    method: str = "didim",
    *,
    offset: bool = False,
    apM: Optional[float] = None,
    initial: Optional[Dict[str, float]] = None,
    criterion: str = "force",
    progress: Progress = None,
    **options,
) -> IdentificationResult:
    """Identifies the ``model`` ("rigid" or "flexible") of a recording with ``method``:

    - ``"idim-ls"``: inverse model on measured positions (the flexible model needs the load position ``ql``);
    - ``"didim"``: rigid DIDIM, or for "flexible" the three-step procedure (rigid DIDIM, Nelder-Mead on
      (λ, f_n_flex), flexible DIDIM);
    - ``"oe-nm"``: Nelder-Mead on all parameters, criterion J_τ ("force") or J_q ("position"), eq. (32);
    - ``"oe-gn"``: Levenberg-Marquardt with exact closed-loop sensitivities.

    The output-error methods start, unless ``initial`` is given, from (apM, 0, 0) for the rigid model and from the
    pseudo-regular values of eq. (33) built on a rigid DIDIM for the flexible one (its simulations are counted).
    ``apM`` is the a priori total mass (kg); by default a rough value from the reference is used. Other keyword
    options go to the method's function (e.g. ``cutoff_hz``, ``tol``, ``max_iter``, ``substeps``).
    """
    if model not in MODELS:
        raise DataError(f"unknown model {model!r}: use one of {', '.join(MODELS)}")
    if method not in METHODS:
        raise DataError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    if not isinstance(recording, Recording):
        raise DataError(f"recording must be a didim.Recording (see didim.load_mat), got {type(recording).__name__}")
    if method == "idim-ls":
        return idim_ls(recording, model, offset=offset, **options)
    if method == "didim":
        if model == "rigid":
            return didim_rigid(recording, apM, offset=offset, progress=progress, **options)
        return didim_flexible(recording, apM, offset=offset, progress=progress, **options)

    t0 = time.perf_counter()
    pre: Optional[IdentificationResult] = None
    if initial is None:
        m0 = apM if apM is not None else reference_mass(recording)
        if model == "rigid":
            initial = {"M": m0, "Fv": 0.0, "Fc": 0.0, **({"OF": 0.0} if offset else {})}
        else:
            pre = didim_rigid(recording, m0, offset=offset, progress=progress)
            initial = pseudo_regular_initial(pre.params)
    solver = oe_nm if method == "oe-nm" else oe_gn
    if method == "oe-nm" and model == "rigid" and any(v == 0 for v in initial.values()):
        # Nelder-Mead scales by the initial values: zero frictions start from a small fraction of the force scale
        initial = {k: (v if v != 0 else 1.0) for k, v in initial.items()}
    r = solver(recording, model, initial, criterion=criterion, progress=progress, **options)
    if pre is not None:
        r.steps = {"rigid": pre}
        r.simulations += pre.simulations
    r.elapsed_s = time.perf_counter() - t0
    return r


__all__ = ["identify", "METHODS"]
