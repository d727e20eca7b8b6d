"""Robustness sweeps: points, the statistics, local and Dask execution through the same code path, the CLI."""

import json

import numpy as np
import pytest

from didim.cli import main
from didim.sweep import SCENARIOS, grid_points, parse_values, random_points, run_point, step_truth, sweep

RIGID = dict(scenario="rigid-emps", model="rigid", method="didim")


def test_points_of_a_grid_and_of_random_draws_are_reproducible():
    pts = grid_points(dict(apM=[25, 100], seed=[0, 1, 2]), dict(model="rigid"))
    assert len(pts) == 6 and pts[0] == dict(model="rigid", apM=25, seed=0) and pts[-1]["seed"] == 2
    a = random_points(dict(apM=(25, 1000, "log"), seed=(0, 9, "int")), 20, seed=3)
    assert a == random_points(dict(apM=(25, 1000, "log"), seed=(0, 9, "int")), 20, seed=3)
    assert all(25 <= p["apM"] <= 1000 and isinstance(p["seed"], int) for p in a)
    assert parse_values("1,2.5,x") == [1, 2.5, "x"]
    assert parse_values("25:1000:3:log") == pytest.approx([25, 158.11388, 1000])


def test_step_truth_maps_the_flexible_truth_to_the_quantities_of_each_step():
    t = SCENARIOS["flexible-motor-friction"]["truth"]
    assert step_truth(t, "rigid") == dict(M=106.0, Fv=200.5, Fc=19.5)
    m = step_truth(t, "mode")
    assert m["lambda"] == pytest.approx(68 / 106) and m["f_n_flex"] == pytest.approx(24.2198, rel=1e-4)


@pytest.fixture(scope="module")
def serial():
    return sweep(grid_points(dict(apM=[25.0, 300.0], seed=[0, 1]), RIGID), executor="serial", progress=False)


def test_rigid_didim_sweep_converges_to_the_truth_with_honest_sigma(serial):
    assert serial.convergence_rate() == 1.0 and all(serial.agrees())
    assert serial.varied() == ["apM", "seed"]
    rows = {r["name"]: r for r in serial.spread()}
    for name in ("M", "Fv", "Fc"):
        assert rows[name]["consensus"] == pytest.approx(SCENARIOS["rigid-emps"]["truth"][name], rel=0.02)
        assert rows[name]["z_rms"] < 5
    assert [r["point"]["apM"] for r in serial.results] == [25.0, 25.0, 300.0, 300.0]
    text = serial.summary()
    assert "4 runs" in text and "by apM: 25: 2/2, 300: 2/2" in text
    d = json.loads(serial.to_json())
    assert d["convergence_rate"] == 1.0 and len(d["results"]) == 4


def test_a_failing_point_is_reported_not_raised():
    r = run_point(dict(scenario="no-such-scenario"))
    assert r["converged"] is False and "unknown scenario" in r["error"]


def test_local_processes_give_the_serial_results(serial):
    par = sweep(serial.points, workers=2, executor="process", progress=False)
    for a, b in zip(serial.results, par.results):
        assert a["params"] == b["params"]


def test_dask_cluster_runs_the_same_code_path(serial):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        with distributed.Client(cluster) as client:
            res = sweep(serial.points, executor=client, progress=False)
    for a, b in zip(serial.results, res.results):
        assert a["params"] == b["params"]


def test_sweep_cli_writes_the_report_and_the_plot(tmp_path, capsys):
    js, png = tmp_path / "s.json", tmp_path / "s.png"
    rc = main(["sweep", "--scenario", "rigid-emps", "--model", "rigid", "--grid", "apM=25,1000", "--seeds", "1",
               "--workers", "1", "--json", str(js), "--plot", str(png), "--quiet"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "2 runs" in out and "2 converged" in out
    assert json.loads(js.read_text())["convergence_rate"] == 1.0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["sweep", "--scenario", "rigid-emps", "--quiet"]) == 2  # nothing to sweep: a user error


def test_progress_is_one_line_per_point_in_a_log(capsys):
    """Redrawn in place (\\r) only on a terminal: captured in a log, each point is a line of its own (a helper's log
    showed the bars run together on one line)."""
    from didim.sweep import _Bar

    bar = _Bar(3, True, "sweep")
    for ok in (True, False, True):
        bar.update(ok)
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.splitlines()
    assert len(lines) == 3 and lines[-1].startswith("sweep [") and "3/3, 2 converged" in lines[-1], lines
