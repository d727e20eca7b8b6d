"""The command line, run as a user would."""

import json
import subprocess
import sys


def run(*args):
    return subprocess.run([sys.executable, "-m", "didim", *args], capture_output=True, text=True, timeout=600)


def test_identify_writes_the_json_contract(emps_path, tmp_path):
    out = tmp_path / "r.json"
    p = run("identify", str(emps_path), "--method", "idim-ls", "--offset", "--json", str(out), "--quiet")
    assert p.returncode == 0, p.stderr
    d = json.loads(out.read_text())
    for key in ("model", "method", "params", "std", "rel_std_pct", "relative_error", "iterations", "simulations", "elapsed_s"):
        assert key in d
    assert d["model"] == "rigid" and set(d["params"]) == {"M", "Fv", "Fc", "OF"}
    assert round(d["params"]["M"], 4) == 95.1089


def test_identify_didim_with_plot(emps_path, tmp_path):
    png = tmp_path / "fit.png"
    p = run("identify", str(emps_path), "--method", "didim", "--apm", "78", "--plot", str(png), "--quiet")
    assert p.returncode == 0, p.stderr
    assert png.stat().st_size > 10_000
    assert "didim identification of the rigid model" in p.stdout


def test_user_errors_exit_2_with_one_line_and_no_traceback(tmp_path):
    p = run("identify", str(tmp_path / "missing.mat"))
    assert p.returncode == 2
    assert p.stderr.strip().count("\n") == 0
    assert "no such file" in p.stderr and "Traceback" not in p.stderr
