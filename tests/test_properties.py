"""Property-based tests: random and hostile arrays and parameters thrown at every function of ``didim._core`` and at
the main Python API. The only outcomes allowed are a result or a documented exception: DataError, SimulationError,
IdentifiabilityError, DidimError (never its "internal error", which would be a caught Rust panic), and TypeError for
an argument of the wrong Python type.

Examples per test: the "ci" profile (default, derandomized so CI is reproducible) or, for a local campaign,
``DIDIM_HYPOTHESIS_PROFILE=fuzz`` with ``DIDIM_FUZZ_EXAMPLES`` examples per test (default 2000). Every run writes the
number of examples tried per test to ``$DIDIM_FUZZ_REPORT`` when that is set.
"""

from __future__ import annotations

import json
import math
import os
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import didim
from didim import _core

settings.register_profile(
    "ci",
    max_examples=int(os.environ.get("DIDIM_CI_EXAMPLES", "40")),
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=list(HealthCheck),
)
settings.register_profile(
    "fuzz",
    max_examples=int(os.environ.get("DIDIM_FUZZ_EXAMPLES", "2000")),
    deadline=None,
    suppress_health_check=list(HealthCheck),
)
PROFILE = os.environ.get("DIDIM_HYPOTHESIS_PROFILE", "ci")

ALLOWED = (didim.DidimError, TypeError)
_COUNTS: dict = {}


def attempt(f, *args, **kwargs):
    """Calls ``f``; returns its result, or None when it raised an allowed exception. Anything else fails the test."""
    name = getattr(f, "__qualname__", repr(f))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", didim.DidimWarning)
            out = f(*args, **kwargs)
        _tally(name, "result")
        return out
    except ALLOWED as e:
        assert "internal error" not in str(e), f"a Rust panic reached Python: {e}"
        assert str(e).strip(), f"{type(e).__name__} without a message"
        _tally(name, type(e).__name__)
        return None


def _tally(name: str, outcome: str) -> None:
    key = (name, outcome)
    _COUNTS[key] = _COUNTS.get(key, 0) + 1


@pytest.fixture(scope="module", autouse=True)
def _report():
    yield
    path = os.environ.get("DIDIM_FUZZ_REPORT")
    if path:
        with open(path, "a", encoding="utf-8") as f:
            for (name, outcome), v in sorted(_COUNTS.items()):
                f.write(f"{PROFILE}\t{name}\t{outcome}\t{v}\n")


def prop(test):
    return settings.get_profile(PROFILE)(test)


# ---------------------------------------------------------------------------------------------------------------------
# Strategies
# ---------------------------------------------------------------------------------------------------------------------

EXTREMES = [0.0, -0.0, 1.0, -1.0, math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 2.2e-308, 1e-300, 1e300]
floats = st.one_of(st.floats(-10, 10), st.sampled_from(EXTREMES), st.floats(allow_nan=True, allow_infinity=True))
moderate = st.floats(0.01, 100.0)


def sometimes(good, bad=floats):
    """Mostly sensible values (to get deep into the code), sometimes hostile ones."""
    return st.one_of(good, good, good, bad)


@st.composite
def arrays(draw, max_len: int = 60, ndim=None):
    """Hostile arrays: empty, 0-d, 1-D/2-D, non-contiguous, Fortran order, wrong dtypes, lists, None."""
    n = draw(st.integers(0, max_len))
    kind = draw(st.sampled_from(["clean", "clean", "hostile", "extreme"]))
    if kind == "clean":
        base = draw(st.lists(st.floats(-1, 1), min_size=n, max_size=n))
    elif kind == "hostile":
        base = draw(st.lists(floats, min_size=n, max_size=n))
    else:
        base = [draw(st.sampled_from(EXTREMES))] * n
    a = np.array(base, dtype=float)
    shape = draw(st.sampled_from(["1d", "1d", "1d", "col", "row", "2rows", "0d", "strided", "fortran"]))
    if ndim == 2:
        shape = draw(st.sampled_from(["col", "row", "2rows", "fortran", "1d"]))
    if shape == "col":
        a = a[:, None]
    elif shape == "row":
        a = a[None, :]
    elif shape == "2rows":
        a = np.vstack([a, a[::-1]])
    elif shape == "0d":
        a = np.array(a[0] if n else 0.0)
    elif shape == "strided":
        a = np.repeat(a, 2)[::2]
    elif shape == "fortran":
        a = np.asfortranarray(np.vstack([a, a]).T)
    dtype = draw(st.sampled_from(["f8", "f8", "f8", "f8", "f4", "i8", "bool", "c16", "object", "list", "none"]))
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if dtype == "list":
            return a.tolist()
        if dtype == "none":
            return None
        if dtype in ("i8",):
            return np.nan_to_num(a, nan=0, posinf=0, neginf=0).astype(np.int64)
        return a.astype(dtype)


def clean_signal(n):
    return st.lists(st.floats(-0.2, 0.2), min_size=n, max_size=n).map(np.array)


gains = st.one_of(
    st.lists(sometimes(st.floats(1, 500)), min_size=4, max_size=4),
    st.lists(sometimes(st.floats(1, 1e5)), min_size=3, max_size=3),
    st.lists(floats, max_size=6),
)
whole = st.one_of(st.integers(0, 12), st.sampled_from([-1, -(2**63), 2**63, 2**64 + 1, 100_001, 10**30]))
models = st.sampled_from(["rigid", "flexible", "elastic", ""])


def mutated(data, valid: dict, hostile: dict) -> dict:
    """The valid arguments with up to two of them replaced by hostile draws: about a third of the cases run the
    function to its end, the others probe one or two bad arguments at a time (and how they combine)."""
    keys = data.draw(st.lists(st.sampled_from(sorted(hostile)), max_size=2, unique=True), label="hostile arguments")
    return {**valid, **{k: data.draw(hostile[k], label=k) for k in keys}}


def smooth(n):
    """A reference-like signal of n samples (a random walk of bounded steps)."""
    return st.lists(st.floats(-2e-3, 2e-3), min_size=n, max_size=n).map(lambda v: np.cumsum(v) if v else np.zeros(0))


FLEX = [68.0, 104.0, 10.0, 38.0, 96.5, 9.5, 8.8e5]


@st.composite
def sim_args(draw):
    """Valid arguments of a closed-loop simulation: model, params, qr, dt, controller, gains and the keyword options
    of _core.Problem."""
    model = draw(st.sampled_from(["rigid", "flexible"]))
    offset = draw(st.booleans())
    n = draw(st.integers(3, 150))
    if model == "rigid":
        params = [draw(st.floats(1, 200)), draw(st.floats(0, 300)), draw(st.floats(0, 30))]
    else:
        params = [v * draw(st.floats(0.5, 2)) for v in FLEX]
    if offset:
        params.append(draw(st.floats(-5, 5)))
    controller = draw(st.sampled_from(["emps", "pd"]))
    if controller == "emps":
        gains = [draw(st.floats(10, 300)), draw(st.floats(10, 300)), draw(st.floats(1, 50)),
                 draw(st.sampled_from([10.0, math.inf]))]
    else:
        gains = [draw(st.floats(1e3, 1e5)), draw(st.floats(10, 1e3)), draw(st.sampled_from([100.0, math.inf]))]
    return dict(model=model, params=np.array(params), qr=draw(smooth(n)), dt=draw(st.floats(2e-4, 2e-3)),
                controller=controller, gains=gains, u_ext=draw(st.one_of(st.none(), smooth(n).map(lambda x: 100 * x))),
                substeps=draw(st.integers(1, 12)), quantization=draw(st.sampled_from([0.0, 5e-8])),
                delay=draw(st.integers(0, 2)), coulomb_eps=draw(st.sampled_from([1e-4, 0.0])), offset=offset)


SIM_HOSTILE = dict(model=models, params=arrays(10), qr=arrays(150), dt=floats,
                   controller=st.sampled_from(["pid", "", "EMPS"]), gains=gains, u_ext=arrays(150),
                   substeps=st.one_of(whole, st.floats()), quantization=floats, delay=whole, coulomb_eps=floats,
                   offset=st.one_of(st.integers(), st.none()))


# ---------------------------------------------------------------------------------------------------------------------
# didim._core
# ---------------------------------------------------------------------------------------------------------------------


@prop
@given(model=st.one_of(models, st.integers(), st.none()), offset=st.one_of(st.booleans(), st.integers()))
def test_core_param_names_never_panics(model, offset):
    m = attempt(_core.Model, model, offset=offset)
    if m is not None:
        assert list(m.names)[:3] in (["M", "Fv", "Fc"], ["M1", "Fv1", "Fc1"])


@prop
@given(data=st.data(), sens=st.booleans())
def test_core_simulate_never_panics(data, sens):
    a = mutated(data, data.draw(sim_args()), SIM_HOSTILE)
    params = a.pop("params")
    model = attempt(_core.Model, a.pop("model"), offset=a.pop("offset"), coulomb_eps=a.pop("coulomb_eps"),
                    actuation=[("delay", a.pop("delay"))])
    if model is None:
        return
    pos = [model] + [a.pop(k) for k in ("qr", "dt", "controller", "gains")]
    pb = attempt(_core.Problem, *pos, **a)
    out = None if pb is None else attempt(pb.simulate_sensitivity if sens else pb.simulate, params)
    if out is not None:
        n = len(pos[1])
        for k, v in out.items():
            assert v.shape[-1] == n and np.all(np.isfinite(v)), k


@prop
@given(data=st.data())
def test_core_regressor_never_panics(data):
    ndof = data.draw(st.sampled_from([1, 2]))
    n = data.draw(st.integers(0, 60))
    sig = st.lists(st.lists(st.floats(-1, 1), min_size=n, max_size=n), min_size=ndof, max_size=ndof).map(np.array)
    valid = dict(model="rigid" if ndof == 1 else "flexible", q=data.draw(sig), qd=data.draw(sig), qdd=data.draw(sig),
                 coulomb_eps=data.draw(st.sampled_from([1e-4, 0.0])), offset=data.draw(st.booleans()))
    hostile = dict(model=models, q=arrays(60, ndim=2), qd=arrays(60, ndim=2), qdd=arrays(60, ndim=2), coulomb_eps=floats,
                   offset=st.integers())
    a = mutated(data, valid, hostile)
    model = attempt(_core.Model, a.pop("model"), offset=a.pop("offset"), coulomb_eps=a.pop("coulomb_eps"))
    w = None if model is None else attempt(model.regressor, a.pop("q"), a.pop("qd"), a.pop("qdd"))
    if w is not None:
        assert np.all(np.isfinite(w))


@prop
@given(data=st.data())
def test_core_lstsq_never_panics(data):
    r, c = data.draw(st.integers(0, 40)), data.draw(st.integers(0, 6))
    wc = np.array(data.draw(st.lists(st.floats(-1, 1), min_size=r * c, max_size=r * c))).reshape(r, c)
    if c >= 2 and data.draw(st.booleans()):
        wc[:, 1] = 2 * wc[:, 0]  # a dependent column: the solution names it
    valid = dict(w=wc, y=np.array(data.draw(st.lists(st.floats(-1, 1), min_size=r, max_size=r))), rank_tol=None,
                 sigma=data.draw(st.sampled_from(["paper", "sample_std"])))
    hostile = dict(w=arrays(60, ndim=2), y=arrays(60), rank_tol=floats, sigma=st.sampled_from(["other", ""]))
    a = mutated(data, valid, hostile)
    w = a.pop("w")
    sol = attempt(_core.lstsq, w, a.pop("y"), **a)
    if sol is not None:
        assert np.all(np.isfinite(sol["params"])) and 1 <= sol["rank"] <= np.shape(w)[1]


@prop
@given(data=st.data())
def test_core_filter_designs_never_panic(data):
    valid = dict(order=data.draw(st.integers(1, 12)), wn=data.draw(st.floats(0.01, 0.99)),
                 rp=data.draw(st.floats(0.01, 3)), sos=data.draw(st.booleans()))
    a = mutated(data, valid, dict(order=whole, wn=floats, rp=floats, sos=st.integers()))
    attempt(_core.butter, a["order"], a["wn"], sos=a["sos"])
    attempt(_core.cheby1, a["order"], a["rp"], a["wn"], sos=a["sos"])


@prop
@given(data=st.data())
def test_core_zero_phase_filters_never_panic(data):
    order = data.draw(st.integers(1, 8))
    wn = data.draw(st.floats(0.05, 0.95))
    b, aa = _core.butter(order, wn)
    n = data.draw(st.integers(0, 120))
    valid = dict(b=list(b), a=list(aa), sos=_core.butter(order, wn, sos=True),
                 x=np.array(data.draw(st.lists(st.floats(-1, 1), min_size=n, max_size=n))),
                 padlen=data.draw(st.one_of(st.none(), st.integers(0, 40))))
    hostile = dict(b=st.one_of(st.lists(floats, max_size=6), arrays(6)), a=st.one_of(st.lists(floats, max_size=6), arrays(6)),
                   sos=arrays(12, ndim=2), x=arrays(120), padlen=whole)
    a = mutated(data, valid, hostile)
    y = attempt(_core.filtfilt, a["b"], a["a"], a["x"], padlen=a["padlen"])
    if y is not None:
        assert y.shape == np.shape(a["x"]) and np.all(np.isfinite(y))
    attempt(_core.sosfiltfilt, a["sos"], a["x"], padlen=a["padlen"])


@prop
@given(data=st.data())
def test_core_decimate_never_panics(data):
    n = data.draw(st.integers(0, 400))
    p = data.draw(st.integers(0, 4))
    kind = data.draw(st.sampled_from(["butter", "matlab"]))
    valid = dict(y=np.array(data.draw(st.lists(st.floats(-1, 1), min_size=n, max_size=n))),
                 w=np.array(data.draw(st.lists(st.floats(-1, 1), min_size=n * p, max_size=n * p))).reshape(n, p)
                 if p else None,
                 factor=data.draw(st.integers(1, 20)), kind=kind, order=data.draw(st.integers(1, 8)),
                 cutoff_hz=data.draw(st.floats(1, 40)) if kind == "butter" else None,
                 fs_hz=1000.0 if kind == "butter" else None, form=data.draw(st.sampled_from(["sos", "ba"])))
    hostile = dict(y=arrays(400), w=arrays(400, ndim=2), factor=whole, kind=st.sampled_from(["cheby", ""]), order=whole,
                   cutoff_hz=floats, fs_hz=floats, form=st.sampled_from(["zpk", ""]))
    a = mutated(data, valid, hostile)
    out = attempt(_core.decimate, a.pop("y"), a.pop("w"), **a)
    if out is not None:
        yd, wd = out
        assert np.all(np.isfinite(yd)) and (wd is None or np.all(np.isfinite(wd)))


@prop
@given(fs=floats, cutoff=floats)
def test_core_default_factor_never_panics(fs, cutoff):
    r = attempt(_core.default_factor, fs, cutoff)
    assert r is None or r >= 1


# ---------------------------------------------------------------------------------------------------------------------
# The Python API
# ---------------------------------------------------------------------------------------------------------------------


@st.composite
def record_args(draw, max_n=300, min_n=3):
    """A valid record: a random walk plus a sine as reference, the motor close to it, a force of a random scale
    (sometimes absurd: 0, 1e±200, volts), either controller, optional load position and external force. Long arrays
    come from a seeded generator so that Hypothesis's buffer stays small."""
    n = draw(st.integers(min_n, max_n))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    t = np.arange(n) * 1e-3
    amp = draw(st.sampled_from([0.0, 0.05, 0.1]))
    qr = np.cumsum(rng.uniform(-2e-3, 2e-3, n)) * draw(st.sampled_from([0.0, 1.0])) + amp * np.sin(
        2 * np.pi * draw(st.floats(0.5, 5)) * t)
    scale = draw(st.sampled_from([1.0, 1.0, 1.0, 1e-200, 1e200, 0.0, 1 / 35.15]))
    pd = draw(st.booleans())
    return dict(
        dt=draw(st.sampled_from([1e-3, 1e-3, 5e-4, 2e-3])),
        qr=qr,
        force=scale * rng.uniform(-100, 100, n),
        qm=qr + rng.uniform(-1e-5, 1e-5, n),
        controller=didim.PD(4e4, 600.0, draw(st.sampled_from([math.inf, 50.0]))) if pd else didim.EmpsCascade(),
        ql=qr[::-1].copy() if draw(st.booleans()) else None,
        u_ext=100 * rng.standard_normal(n) if draw(st.booleans()) else None,
        position_resolution=draw(st.sampled_from([None, 5e-8])),
    )


REC_HOSTILE = dict(dt=st.one_of(floats, st.none(), st.text(max_size=3)), qr=arrays(60), force=arrays(60), qm=arrays(60),
                   ql=arrays(60), u_ext=arrays(60), position_resolution=st.one_of(floats, st.text(max_size=2)),
                   controller=st.one_of(st.none(), st.integers()))


@prop
@given(data=st.data(), kp=sometimes(moderate), kd=sometimes(moderate), pd=st.booleans())
def test_recording_never_raises_undocumented(data, kp, kd, pd):
    attempt(didim.PD, kp, kd) if pd else attempt(didim.EmpsCascade, kp=kp, kv=kd)
    a = mutated(data, data.draw(record_args(60)), REC_HOSTILE)
    rec = attempt(didim.Recording, **a)
    if rec is not None:
        assert isinstance(rec.diagnose(), list)
        repr(rec)


@prop
@given(data=st.data())
def test_simulate_never_raises_undocumented(data):
    rec = didim.Recording(**data.draw(record_args(200)))
    model = data.draw(st.sampled_from(["rigid", "flexible"]))
    params = dict(M=95.0, Fv=200.0, Fc=20.0) if model == "rigid" else dict(zip(didim.param_names("flexible"), FLEX))
    valid = dict(params=params, model=model, offset=None, substeps=data.draw(st.integers(1, 12)), quantization=None,
                 delay=data.draw(st.integers(0, 2)), coulomb_eps=1e-4)
    hostile = dict(params=st.one_of(st.dictionaries(st.sampled_from(["M", "Fv", "Fc", "OF", "M1", "K12", "X"]), floats,
                                                    max_size=5), st.lists(floats, max_size=8), arrays(8),
                                    st.text(max_size=3)),
                   model=models, offset=st.integers(), substeps=st.one_of(whole, st.floats()),
                   quantization=st.one_of(floats, st.text(max_size=2)), delay=st.one_of(whole, st.floats()),
                   coulomb_eps=st.one_of(floats, st.none()))
    a = mutated(data, valid, hostile)
    sim = attempt(didim.simulate, rec, a.pop("params"), a.pop("model"), **a)
    if sim is not None:
        assert np.all(np.isfinite(sim.force))
        sim.relative_error(rec)


@prop
@given(data=st.data(), model=st.sampled_from(["rigid", "flexible"]),
       method=st.sampled_from(["idim-ls", "didim", "didim", "oe-nm", "oe-gn"]))
def test_identify_never_raises_undocumented(data, model, method):
    rec = didim.Recording(**data.draw(record_args(2500, min_n=400)))
    valid = dict(offset=data.draw(st.booleans()), apM=None if method == "idim-ls" else 50.0)
    if method != "idim-ls":
        valid.update(max_iter=2, substeps=data.draw(st.integers(1, 4)))
    if method == "didim" and model == "rigid":
        valid.update(cutoff_hz=data.draw(st.floats(5, 60)))
    hostile = dict(offset=st.integers(), apM=floats, max_iter=st.one_of(whole, st.floats()),
                   substeps=st.one_of(whole, st.floats()), cutoff_hz=floats, tol=floats, bogus=st.just(1),
                   coulomb_eps=floats, initial=st.dictionaries(st.sampled_from(["M", "Fv", "Fc", "M1"]), floats))
    a = mutated(data, valid, hostile)
    r = attempt(didim.identify, rec, model, method, **a)
    if r is not None:
        assert isinstance(r.converged, bool)
        json.loads(r.to_json())
        r.summary()


@prop
@given(data=st.data())
def test_signal_functions_never_raise_undocumented(data):
    from didim.signal import default_factor, diffcent, lowpass

    n = data.draw(st.integers(0, 300))
    valid = dict(x=np.array(data.draw(st.lists(st.floats(-1, 1), min_size=n, max_size=n))),
                 cutoff=data.draw(st.floats(1, 100)), fs=1000.0, order=data.draw(st.integers(1, 8)),
                 factor=data.draw(st.one_of(st.none(), st.integers(1, 20))),
                 padding=data.draw(st.sampled_from(["scipy", "matlab"])), dt=1e-3)
    hostile = dict(x=arrays(300), cutoff=floats, fs=floats, order=whole, factor=whole,
                   padding=st.sampled_from(["other", ""]), dt=floats)
    a = mutated(data, valid, hostile)
    attempt(lowpass, a["x"], a["cutoff"], a["fs"], order=a["order"], padding=a["padding"])
    attempt(default_factor, a["fs"], a["cutoff"])
    attempt(diffcent, a["x"], a["dt"])
    dec = attempt(didim.Decimation.lowpass, a["cutoff"], a["fs"], order=a["order"], factor=a["factor"])
    if dec is not None:
        attempt(dec.apply, a["x"], a["x"])
    dec = attempt(didim.Decimation.matlab, a["factor"] or 10)
    if dec is not None:
        attempt(dec.apply, a["x"])


@prop
@given(content=st.one_of(st.binary(max_size=400), st.sampled_from([b"", b"MATLAB 5.0 MAT-file" + b" " * 200])),
       cut=st.integers(0, 700_000))
def test_load_mat_never_raises_undocumented(tmp_path_factory, content, cut, emps_path):
    folder = tmp_path_factory.mktemp("mat")
    junk = folder / "junk.mat"
    junk.write_bytes(content)
    attempt(didim.load_mat, junk)
    with open(emps_path, "rb") as f:
        head = f.read(cut)
    cut_file = folder / "cut.mat"
    cut_file.write_bytes(head)
    attempt(didim.load_mat, cut_file)


@prop
@given(data=st.data())
def test_helpers_and_scenarios_never_raise_undocumented(data):
    attempt(didim.coulomb_sign, data.draw(arrays(20)), data.draw(st.one_of(floats, st.just(1e-4))))
    attempt(didim.param_names, data.draw(st.one_of(models, st.none())), data.draw(st.one_of(st.booleans(), st.integers())))
    n = data.draw(st.integers(0, 50))
    t = np.arange(n) * data.draw(st.sampled_from([1e-3, -1e-3, 0.0]))
    if data.draw(st.booleans()):
        t = data.draw(arrays(50))
    attempt(didim.Recording.from_time, t, np.zeros(n), np.zeros(n), np.zeros(n),
            dt=data.draw(st.one_of(st.none(), floats)))
    valid = dict(truth=dict(sc_truth()), model="rigid", qr=0.05 * np.sin(np.arange(300) * 2e-2),
                 force_noise=1.0, noise_corr=0.5, quantization=5e-8, seed=data.draw(st.integers(0, 10)))
    hostile = dict(truth=st.dictionaries(st.sampled_from(["M", "Fv", "Fc", "K12"]), floats), model=models,
                   qr=arrays(300), force_noise=floats, noise_corr=floats, quantization=st.one_of(floats, st.none()),
                   seed=st.one_of(st.integers(), st.text(max_size=2)))
    a = mutated(data, valid, hostile)
    rec = attempt(didim.scenarios.make_recording, a.pop("truth"), a.pop("model"), a.pop("qr"), **a)
    if rec is not None:
        assert np.all(np.isfinite(rec.force))


def sc_truth():
    return dict(M=95.0, Fv=200.0, Fc=20.0)


json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), st.floats(allow_nan=False), st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=12,
)
_RESULT_KEYS = ["model", "method", "params", "std", "rel_std_pct", "relative_error", "iterations", "simulations",
                "elapsed_s", "converged", "message", "initial", "output_error", "history", "frozen", "options", "steps",
                "notes", "structure", "force_error"]
_STRUCTURE_KEYS = ["kind", "offset", "terms", "delay", "backlash_gap", "coulomb_eps"]


@prop
@given(data=st.data())
def test_load_result_refuses_any_edited_file_with_a_data_error(tmp_path_factory, data):
    """A saved result with any field replaced by any JSON value loads, or raises DataError naming the problem (the
    second hostile campaign found TypeError, AttributeError, ValueError and RecursionError here)."""
    d = {"model": "rigid", "method": "didim", "params": {"M": 95.0, "Fv": 200.0, "Fc": 20.0},
         "structure": {"kind": "rigid", "offset": False, "terms": [], "delay": 0, "backlash_gap": None,
                       "coulomb_eps": 1e-4}, "history": [{"k": 1, "params": {"M": 90.0}}], "steps": {}, "notes": []}
    for _ in range(data.draw(st.integers(1, 3))):
        if data.draw(st.booleans()):
            d[data.draw(st.sampled_from(_RESULT_KEYS))] = data.draw(json_values)
        elif isinstance(d.get("structure"), dict):
            d["structure"][data.draw(st.sampled_from(_STRUCTURE_KEYS))] = data.draw(json_values)
    p = tmp_path_factory.mktemp("r") / "r.json"
    p.write_text(json.dumps(d))
    try:
        r = didim.load_result(p)
    except didim.DataError as e:
        assert str(e).strip()
        _tally("load_result", "DataError")
        return
    _tally("load_result", "result")
    assert isinstance(r, didim.IdentificationResult)


@prop
@given(spec=st.dictionaries(st.sampled_from(["type", "dt", "b_r", "a_r", "b_y", "a_y", "saturation", "gain", "kp", "kv",
                                             "kd", "ti", "kff", "f_lp", "notch_hz", "tau_max"]),
                            json_values, max_size=8),
       kind=st.sampled_from(["transfer_function", "cascade", "emps", "pd", "nope", None]))
def test_load_controller_refuses_any_malformed_file_with_a_data_error(tmp_path_factory, spec, kind):
    if kind is not None:
        spec["type"] = kind
    p = tmp_path_factory.mktemp("c") / "c.json"
    p.write_text(json.dumps(spec))
    try:
        didim.load_controller(p)
        _tally("load_controller", "result")
    except didim.DataError as e:
        assert str(e).strip()
        _tally("load_controller", "DataError")
