"""Every Python code block of the README runs as written (in order, in one namespace, in a temporary folder), with
the EMPS records found where the README says they are."""

import os
import re
import warnings
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_blocks_run_as_written(tmp_path, monkeypatch, emps_path):
    import matplotlib

    matplotlib.use("Agg")
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert len(blocks) >= 3
    # the README names ../shared/data/emps relative to a checkout; run from a folder where that path resolves
    work = tmp_path / "checkout"
    work.mkdir()
    (tmp_path / "shared" / "data").mkdir(parents=True)
    os.symlink(Path(emps_path).parent, tmp_path / "shared" / "data" / "emps")
    from conftest import TRUTHBENCH_DIR

    if not (TRUTHBENCH_DIR / "drive").is_dir():
        pytest.skip(f"the README's drive example reads {TRUTHBENCH_DIR / 'drive'}, not available")
    os.symlink(TRUTHBENCH_DIR, tmp_path / "shared" / "data" / "truthbench")
    from conftest import ROBOTS_DIR

    if not (ROBOTS_DIR / "truth.json").exists():
        pytest.skip(f"the README's robot example reads {ROBOTS_DIR}, not available")
    os.symlink(ROBOTS_DIR, tmp_path / "shared" / "data" / "robots")
    from conftest import FLEXROBOTS_DIR

    if not (FLEXROBOTS_DIR / "truth.json").exists():
        pytest.skip(f"the README's elastic-joint example reads {FLEXROBOTS_DIR}, not available")
    os.symlink(FLEXROBOTS_DIR, tmp_path / "shared" / "data" / "flexrobots")
    monkeypatch.chdir(work)
    namespace = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        for i, code in enumerate(blocks):
            exec(compile(code, f"README block {i + 1}", "exec"), namespace)  # noqa: S102 - the README's own code
    assert (work / "fit.png").stat().st_size > 0 and (work / "d.html").stat().st_size > 0
    assert namespace["flex"].converged and namespace["lm"].converged


def test_the_readme_rigid_emps_numbers_are_what_the_code_gives(emps):
    """The README's headline rigid DIDIM numbers on DATA_EMPS are re-measured here, to their printed digits."""
    import didim

    text = README.read_text(encoding="utf-8")
    m = re.search(r"converges to M = ([\d.]+) kg, Fv = ([\d.]+) N/\(m/s\), Fc = ([\d.]+) N,\s+OF = −([\d.]+) N", text)
    assert m, "the README's rigid DIDIM sentence changed: update this test"
    r = didim.identify(emps, "rigid", "didim", offset=True, apM=78.0)
    assert r.converged
    for name, printed, sign in zip(("M", "Fv", "Fc", "OF"), m.groups(), (1, 1, 1, -1)):
        decimals = len(printed.split(".")[1]) if "." in printed else 0
        assert abs(r.params[name] - sign * float(printed)) <= 0.5 * 10 ** -decimals + 1e-6 * abs(r.params[name]), (
            name, r.params[name], printed)
