"""The closed loop and the zero-phase filters run in an AVX2+FMA build where the processor has both (chosen at run
time), else in the baseline build. Both compute the same IEEE operations in the same order (Rust contracts no
multiply-add by itself), so their results must agree to rounding of the last bit at most: a gap would mean the two
builds compute different things."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from didim import _core



def _run(baseline: bool) -> dict:
    code = (
        "import json, numpy as np, didim\n"
        "from didim import _core\n"
        "from didim.scenarios import trapezoid_moving_chirp\n"
        "ctl = didim.EmpsCascade()\n"
        "qr = trapezoid_moving_chirp()\n"
        "rec = didim.Recording(dt=1e-3, qr=qr, force=np.zeros(qr.size), qm=qr, controller=ctl, position_resolution=5e-8)\n"
        "p = dict(M1=68.0, Fv1=104.0, Fc1=10.0, M2=38.0, Fv2=96.5, Fc2=9.5, K12=8.8e5)\n"
        "out = {'build': _core.SIMULATOR_BUILD}\n"
        "for integ in ('exponential', 'rk4'):\n"
        "    s = didim.simulate(rec, p, 'flexible', integrator=integ)\n"
        "    out[integ] = np.concatenate([s.force, s.q.ravel(), s.qd.ravel(), s.qdd.ravel()]).tolist()\n"
        "pb = didim.simulation.problem(rec, 'flexible')\n"
        "sens = pb.simulate_sensitivity(np.array(list(p.values())))\n"
        "out['sens'] = np.asarray(sens['dforce']).ravel().tolist()\n"
        "w = np.column_stack([np.sin(1e-3 * k * np.arange(qr.size)) + k for k in range(1, 8)])\n"
        "dec = [didim.Decimation.lowpass(5.0, 1000.0).apply(qr, w), didim.Decimation.matlab(10).apply(qr, w[:, :2])]\n"
        "out['dec'] = np.concatenate([np.ravel(x) for d in dec for x in d]).tolist()\n"
        "print(json.dumps(out))\n"
    )
    env = dict(os.environ)
    env.pop("DIDIM_BASELINE_SIMD", None)
    if baseline:
        env["DIDIM_BASELINE_SIMD"] = "1"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


@pytest.mark.skipif(_core.SIMULATOR_BUILD == "baseline" and "DIDIM_BASELINE_SIMD" not in os.environ,
                    reason="this processor runs the baseline build only: there is no second build to compare")
def test_the_wide_and_baseline_builds_give_the_same_simulation_and_sensitivities():
    wide, base = _run(False), _run(True)
    assert wide["build"] == "avx2+fma" and base["build"] == "baseline"
    # the zero-phase filters' kernels (groups of columns through the filter together) have their AVX2 build too
    assert np.array_equal(np.asarray(wide["dec"]), np.asarray(base["dec"]))
    for key in ("exponential", "rk4", "sens"):
        a, b = np.asarray(wide[key]), np.asarray(base[key])
        assert a.shape == b.shape and np.all(np.isfinite(a))
        # the same operations in the same order: equal to the last bit; allow 4 ulps of the largest value in case a
        # future compiler orders a sum differently, far below any physical difference (1e-4 relative is the
        # integrator's accuracy target)
        scale = np.max(np.abs(a))
        assert np.max(np.abs(a - b)) <= 4 * np.finfo(float).eps * scale, key
