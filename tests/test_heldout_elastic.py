"""The held-out elastic robots of benches/elastic_robots.py (issue 39's "robots of other kinds"): their plant, a Python
loop over Pinocchio written apart from didim, and didim's elastic closed loop are the same plant. The truth's
parameters in didim's loop replay each record to its truth floor (the noise inside the loop, which didim's loop does
not have) and the link side to the deflection the record logs: on a belt-driven prismatic lift under gravity (K in
N/m, 1 µm encoder, exponential friction law, P + PI cascade, 1 kHz) and on the UR10 (PID, 500 Hz, tanh law), each
with two elastic joints. What didim identifies from these records is measured in docs/elastic_robots.md
(`python benches/elastic_robots.py --held-out`), the three-step DIDIM's failure on the vertical lift among it: not a
test here, because since step 2 starts inside its bounds its search on that stiff 12 s loop runs for more than 15
minutes before it fails."""

import numpy as np
import pytest

import didim
from didim.methods.robot import deflection_errors, force_errors

from conftest import bench_module

pytest.importorskip("pinocchio")


@pytest.mark.parametrize("name", ["lift", "ur10"])
def test_the_truth_in_didims_loop_replays_a_held_out_elastic_robots_record_to_its_floor(name, tmp_path):
    """2 s of training record: the truth's force in didim's loop within 3 % of the record's truth floor (measured
    0.284 % against 0.284 % on the lift, 0.521 % against 0.523 % on the UR10 over the full records), and each elastic
    joint's deflection within 3 % RMS of the logged one (the noise moves the link: the floor of the deflection)."""
    bench = bench_module("elastic_robots")
    cad, truth, records, _ = bench.held_out_robot(name, tmp_path, seconds=(2.0, 1.0))
    rec, floor, _ = records["train"]
    assert rec.ql is not None
    sim = bench.replay_truth(rec, cad, truth)
    err, _ = force_errors(rec, sim["force"])
    assert err == pytest.approx(floor, rel=0.03)
    elastic = [cad.joint_names[j] for j in np.flatnonzero(truth["elastic"])]
    defl = deflection_errors(rec, sim, didim.Model(robot=cad, elastic=elastic))
    assert sorted(defl) == sorted(elastic)
    assert max(defl.values()) < 0.03, defl


def test_a_rigid_step_that_cannot_start_on_an_elastic_record_does_not_blame_a_right_urdf(tmp_path):
    """The UR10 under PID with every elastic joint's harmonics up to 1.4 times the highest mode: whatever rigid DIDIM
    says when it cannot start, the URDF is the robot's (the truth built on it replays the record to its floor). It
    said "the URDF probably does not describe this record's robot"; below another robot's share of the force
    unexplained it now names elastic joints as the other cause."""
    bench = bench_module("elastic_robots")
    cad, truth, records, _ = bench.held_out_robot("ur10_shared", tmp_path, seconds=(16.0, 1.0))
    rec = records["train"][0]
    try:
        didim.identify(rec, cad, "didim")
    except didim.SimulationError as e:
        assert "URDF probably does not describe" not in str(e)
