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


def test_a_misspelled_flag_names_the_flag_meant_and_an_abbreviation_is_refused(emps_path):
    """A subcommand's unknown flag is reported with that subcommand's help and the flag it most resembles; a prefix of
    a flag is not taken for it (``--valid`` ran the doctor as ``--validate``; a flag added later could change its
    meaning)."""
    p = run("doctor", str(emps_path), "--elastc", "3")
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "did you mean --elastic?" in p.stderr and "didim doctor --help" in p.stderr, p.stderr
    p = run("doctor", str(emps_path), "--valid", str(emps_path))
    assert p.returncode == 2 and "did you mean --validate?" in p.stderr, p.stderr
    p = run("identify", str(emps_path), "--foo")
    assert p.returncode == 2 and "did you mean" not in p.stderr and "didim identify --help" in p.stderr, p.stderr
