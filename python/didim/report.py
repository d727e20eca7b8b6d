"""The doctor's HTML report: for each finding the plot where it shows (before and after), the numbers and a sentence
of physics. Self-contained: images are embedded, it opens offline in any browser."""

from __future__ import annotations

import base64
import html
import io
from typing import Any, Dict

import numpy as np

from . import units
from .doctor.words import lead_in_words, start_words
from .doctor.effects import REGISTRY


def _view(effect: str, where: Dict[str, Any], default: Any = "time") -> Any:
    """The residual view where an effect shows (its registry entry's), else where the finding says it lives."""
    e = REGISTRY.get(effect)
    if e is not None:
        return e.view
    view = where.get("view", default)  # "position, moving forward": the position figure shows both directions
    return "position" if isinstance(view, str) and view.startswith("position") else view


def _png(fig) -> str:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _binned(ax, rows, label, color, mirror=False):
    if not rows:
        return
    x = [r[0] for r in rows]
    y = [r[1] for r in rows]
    e = [r[2] for r in rows]
    ax.errorbar(x, y, yerr=e, fmt="o-", ms=3, lw=1, capsize=2, color=color, label=label)


def figure(diag, view: str):
    """One view of the residual, before (the base model) and after (the final model), with 95 % bands."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    before, after = diag.locate["before"], diag.locate["after"]
    axis = diag.final_state.axis
    if view in ("velocity", "position"):
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.4), sharey=True)
        for ax, d in zip(axes, ("forward", "backward")):
            _binned(ax, before[view][d], "before", "tab:red")
            _binned(ax, after[view][d], "after", "tab:blue")
            ax.axhline(0, color="k", lw=0.6)
            ax.set_title(f"moving {d}")
            ax.set_xlabel(f"speed |q̇| ({units.label('m/s', axis)})" if view == "velocity"
                          else f"position q ({units.label('m', axis)})")
            ax.grid(True, alpha=0.3)
        axes[0].set_ylabel(f"mean residual force ({units.force_unit(axis)})")
        axes[0].legend()
    elif view == "spectrum":
        fig, ax = plt.subplots(figsize=(10, 3.4))
        ax.semilogy(before["spectrum"]["f"], before["spectrum"]["psd"], color="tab:red", label="before")
        ax.semilogy(after["spectrum"]["f"], after["spectrum"]["psd"], color="tab:blue", label="after")
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel(f"residual PSD (({units.force_unit(axis)})²/Hz)")
        ax.grid(True, alpha=0.3)
        ax.legend()
    else:  # time
        fig, ax = plt.subplots(figsize=(10, 3.4))
        _binned(ax, before["time"], "before", "tab:red")
        _binned(ax, after["time"], "after", "tab:blue")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"mean residual force ({units.force_unit(axis)})")
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle(f"residual against {view}: base model (red) and final model (blue), 95 % bands", fontsize=10)
    fig.tight_layout()
    return fig


def fit_figure(diag):
    """Measured against simulated force on the training data, base and final model, with the residuals."""
    import matplotlib.pyplot as plt

    ctx = diag._context
    data, hist = ctx["data"], ctx["history"]
    axis = data.rec.axis
    t = diag._context["data"].rec.t
    (_, rt0, _, _), (_, rt1, _, s1) = hist[0], hist[-1]
    fig, axes = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    axes[0].plot(t, data.rec.force, color="tab:red", lw=0.6, label="measured")
    axes[0].plot(t, s1.force, color="tab:blue", lw=0.6, label="simulated (final model)")
    axes[0].set_ylabel(f"motor force ({units.force_unit(axis)})")
    axes[0].legend(loc="upper right")
    td = t[:: data.dec.factor][: len(rt0)]
    axes[1].plot(td, rt0, color="tab:red", lw=0.6, label="residual, base model")
    axes[1].plot(td, rt1, color="tab:blue", lw=0.6, label="residual, final model")
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel(f"decimated residual ({units.force_unit(axis)})")
    axes[1].legend(loc="upper right")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


#: The span (s) of a record's start that :func:`lead_in_figure` shows.
START_SPAN_S = 0.15


def lead_in_figure(diag):
    """The first :data:`START_SPAN_S` of each record with a lead-in (None when none has one): the reference with its
    lead-in before the first sample, the measured and the simulated motor position (mm); the measured force and the
    final model's simulated force through the lead-in and from rest on the first sample (N)."""
    import matplotlib.pyplot as plt
    from dataclasses import replace


    data = diag._context["data"]
    recs = [r for r in (data.rec, data.validate) if r is not None and r.qr_lead.size]
    if not recs:
        return None
    st = diag.final_state
    fig, axes = plt.subplots(2, len(recs), figsize=(10, 5.5), squeeze=False, sharex="col")
    for j, rec in enumerate(recs):
        n_lead, k = rec.qr_lead.size, min(rec.n, max(3, int(round(START_SPAN_S / rec.dt))))
        head = {"qr": rec.qr[:k], "force": rec.force[:k], "qm": rec.qm[:k], "ql": None,
                "u_ext": None if rec.u_ext is None else rec.u_ext[:k]}
        # the lead-in's own samples: the record extended by it (the signals the simulation runs on), simulated from
        # its start as the lead-in is
        qr_ext, u_ext = rec.lead_in_signals()
        ext = replace(rec, qr=qr_ext[:n_lead + k], force=np.r_[np.zeros(n_lead), head["force"]],
                      qm=np.r_[np.full(n_lead, rec.qm[0]), head["qm"]], ql=None, lead_in=None,
                      u_ext=None if u_ext is None else u_ext[:n_lead + k])
        s_led = st.simulate(ext)
        s_rest = st.simulate(replace(rec, **head, lead_in=None))
        t = (np.arange(n_lead + k) - n_lead) * rec.dt * 1e3  # ms
        ax = axes[0][j]
        c, unit = units.plot_length(rec.axis)
        ax.plot(t[:n_lead + 1], c * ext.qr[:n_lead + 1], color="0.5", lw=1.2, ls="--", label="reference, lead-in")
        ax.plot(t[n_lead:], c * head["qr"], color="k", lw=1.0, label="reference")
        ax.plot(t[n_lead:], c * head["qm"], color="tab:red", lw=1.0, label="measured")
        ax.plot(t, c * s_led.q[0], color="tab:blue", lw=1.0, label="simulated")
        ax.set_ylabel(f"motor position ({unit})")
        ax.set_title(rec.name or "record", fontsize=10)
        ax.legend(loc="upper left", fontsize=8)
        ax = axes[1][j]
        ax.plot(t[n_lead:], head["force"], color="tab:red", lw=1.0, label="measured")
        ax.plot(t, s_led.force, color="tab:blue", lw=1.0, label="simulated through the lead-in")
        ax.plot(t[n_lead:], s_rest.force, color="0.5", lw=1.0, ls="--", label="simulated from rest at 0 ms")
        ax.set_xlabel("time from the record's first sample (ms)")
        ax.set_ylabel(f"motor force ({units.force_unit(rec.axis)})")
        ax.legend(loc="upper right", fontsize=8)
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
        ax.axvline(0.0, color="k", lw=0.5)
    fig.tight_layout()
    return fig


def _sigma(x) -> str:
    return "–" if x is None or not np.isfinite(x) else f"{x:.3g}"


def diagnosis_html(diag) -> str:
    e = html.escape
    f = diag.fit
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>didim doctor: " + e(diag.recording) + "</title>",
        "<style>body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
        "th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}.phys{font-style:italic;color:#444}"
        "img{max-width:100%}.rej{color:#777}</style></head><body>",
        f"<h1>didim doctor — {e(diag.recording)}</h1>",
        f"<p>Base model: <b>{e(diag.model)}</b>. Validation: {e(str(diag.options.get('validation')))}. "
        f"Tests at level α = {diag.options['alpha']} (Holm-corrected across candidates, held-out confirmation by "
        f"Diebold–Mariano). Run time {diag.elapsed_s:.1f} s.</p>",
        "<table><tr><th>closed-loop force error</th><th>before</th><th>after</th>"
        "<th>before (decimated, tests)</th><th>after (decimated, tests)</th></tr>",
        f"<tr><td>training</td><td>{100 * f['train_force_before']:.2f} %</td><td>{100 * f['train_force_after']:.2f} %</td>"
        f"<td>{100 * f['train_before']:.2f} %</td><td>{100 * f['train_after']:.2f} %</td></tr>",
        f"<tr><td>validation</td><td>{100 * f['valid_force_before']:.2f} %</td><td>{100 * f['valid_force_after']:.2f} %</td>"
        f"<td>{100 * f['valid_before']:.2f} %</td><td>{100 * f['valid_after']:.2f} %</td></tr></table>",
        "<p>Full rate: ‖τ − τ_sim‖/‖τ‖ on every sample (the benchmark's measure); decimated: the force the tests work "
        "on, without a record's start (below).</p>",
    ]
    # the summary's lines on the controller (checked against the log, or fitted from it) and the friction law
    parts += [f"<p><b>{e(line.split(':')[0].capitalize())}.</b>{e(line.split(':', 1)[1])}</p>"
              for line in diag.summary().splitlines()
              if line.startswith(("controller check", "no controller was described", "friction law"))]
    parts += [f"<p><b>Lead-in.</b> {e(lead_in_words(ld))}</p>" for ld in diag.locate.get("lead_in", [])]
    if diag.locate.get("lead_in"):
        fig = lead_in_figure(diag)
        if fig is not None:
            parts.append(f"<img src='data:image/png;base64,{_png(fig)}'>")
    parts += [f"<p><b>Start.</b> {e(start_words(st))}</p>" for st in diag.locate.get("start", [])]
    parts.append(f"<img src='data:image/png;base64,{_png(fit_figure(diag))}'>")
    if not diag.findings:
        parts.append("<h2>Nothing significant is missing</h2><p>The residual's structure is within what noise explains: "
                     "no candidate effect passes the corrected tests, and no view of the residual (time, speed, "
                     "position) shows significant structure.</p>")
    for i, x in enumerate(diag.findings, 1):
        view = _view(x.effect, x.where)
        if x.words:  # in an engineer's words first, the statistics folded away
            body = (f"<p><b>{e(x.words)}</b>" + (f"; {e(x.held_out())}" if x.held_out() else "") + "</p>"
                    f"<details><summary>statistics</summary><p>{e(x.evidence)}</p></details>")
        else:
            body = f"<p>{e(x.evidence)}</p>"
        parts.append(f"<h2>{i}. {e(x.effect)}</h2><p class='phys'>{e(x.physics)}</p>{body}")
        if x.params:
            parts.append("<table><tr><th>parameter</th><th>value</th><th>σ</th></tr>" + "".join(
                f"<tr><td>{e(k)}</td><td>{v:.5g}</td><td>{_sigma(x.std.get(k))}</td></tr>" for k, v in x.params.items())
                + "</table>")
        parts.append(f"<img src='data:image/png;base64,{_png(figure(diag, view))}'>")
    if diag.ambiguities:
        parts.append("<h2>Effects this record cannot tell apart</h2><ul>" + "".join(
            f"<li>{e(' / '.join(a['effects']))} ({a['shared_pct']:.0f} % shared): {e(a['experiment'])}</li>"
            for a in diag.ambiguities) + "</ul>")
    if diag.rejected:
        parts.append("<h2 class='rej'>Candidates not kept</h2><ul class='rej'>" + "".join(
            f"<li>{e(x.effect)}: {e(x.evidence)}" + (f"<br><b>{e(x.note)}</b>" if x.note else "") + "</li>"
            for x in diag.rejected) + "</ul>")
    parts.append("<h2>Parameters</h2><table><tr><th>parameter</th><th>base fit</th><th>final</th></tr>")
    names = list(dict.fromkeys(list(diag.base.params) + list(diag.final_params)))
    for n in names:
        b, a = diag.base.params.get(n), diag.final_params.get(n)
        parts.append(f"<tr><td>{e(n)}</td><td>{'' if b is None else f'{b:.5g}'}</td><td>{'' if a is None else f'{a:.5g}'}</td></tr>")
    st = diag.final_state
    for label, value in (("delay (samples)", st.model.delay or None), ("force lag (s)", st.model.force_lag or None),
                         ("backlash gap (m)", st.model.backlash_gap)):
        if value is not None:
            parts.append(f"<tr><td>{e(label)}</td><td></td><td>{value:.5g}</td></tr>")
    parts.append("</table><h2>Candidate ranking per round</h2>")
    for r in diag.rounds:
        parts.append(f"<h3>round {r['round']}</h3><table><tr><th>effect</th><th>hyper-parameter</th><th>Wald</th><th>dof</th>"
                     "<th>p</th><th>p (adjusted)</th><th>explained %</th></tr>")
        for c in r["candidates"]:
            hyp = ", ".join(f"{k} = {v:.4g}" for k, v in c["hyper"].items())
            parts.append(f"<tr><td>{e(c['effect'])}</td><td>{e(hyp)}</td><td>{c['wald']:.1f}</td><td>{c['dof']}</td>"
                         f"<td>{c['p_value']:.2g}</td><td>{c['p_adjusted']:.2g}</td><td>{c['explained_pct']:.2f}</td></tr>")
        parts.append("</table>")
    for view in ("velocity", "position", "spectrum", "time"):
        if not any(_view(x.effect, x.where, None) == view for x in diag.findings):
            parts.append(f"<details><summary>residual against {view}</summary>"
                         f"<img src='data:image/png;base64,{_png(figure(diag, view))}'></details>")
    parts.append("</body></html>")
    return "\n".join(parts)


__all__ = ["diagnosis_html", "figure", "fit_figure"]
