"""Nothing lost, nothing half-written: outputs are replaced atomically (a failed or interrupted write leaves the old
file and no temporary file), new files get the usual permissions, and input files are never modified."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import didim  # noqa: E402
from didim.formats import _io  # noqa: E402


def sha256(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def listing(folder):
    return sorted(os.listdir(folder))


@pytest.fixture
def old(tmp_path):
    p = tmp_path / "result.json"
    p.write_text('{"old": true}\n')
    return p


class Boom(Exception):
    pass


def test_a_failing_write_leaves_the_old_file_and_no_temporary_file(old):
    before = listing(old.parent)
    with pytest.raises(Boom):
        with _io.atomic_path(old) as tmp:
            with open(tmp, "w") as f:
                f.write('{"new": ')  # half of the new content ...
            raise Boom  # ... and the run fails
    assert old.read_text() == '{"old": true}\n'
    assert listing(old.parent) == before


def test_an_interrupted_write_leaves_the_old_file(old):
    with pytest.raises(KeyboardInterrupt):
        with _io.atomic_path(old) as tmp:
            open(tmp, "w").write("partial")
            raise KeyboardInterrupt
    assert old.read_text() == '{"old": true}\n' and listing(old.parent) == ["result.json"]


def test_text_that_cannot_be_encoded_does_not_touch_the_old_file(old):
    with pytest.raises(UnicodeEncodeError):
        _io.write_text(old, "valid start, then a lone surrogate \ud800")
    assert old.read_text() == '{"old": true}\n' and listing(old.parent) == ["result.json"]


def test_a_failing_figure_leaves_the_old_png(tmp_path):
    png = tmp_path / "fit.png"
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    _io.save_figure(fig, png)
    good = png.read_bytes()
    with pytest.raises(Exception):
        _io.save_figure(fig, png, dpi=-5)  # matplotlib refuses a negative resolution
    plt.close(fig)
    assert png.read_bytes() == good and listing(tmp_path) == ["fit.png"]


def test_a_successful_write_replaces_the_file_with_the_usual_permissions(tmp_path, old):
    _io.write_text(old, "new\n")
    assert old.read_text() == "new\n"
    new = tmp_path / "fresh.txt"
    _io.write_text(new, "x")
    mask = os.umask(0)
    os.umask(mask)
    assert (new.stat().st_mode & 0o777) == (0o666 & ~mask)  # not mkstemp's 0600
    old.chmod(0o640)
    _io.write_text(old, "again\n")
    assert (old.stat().st_mode & 0o777) == 0o640  # an existing file keeps its mode
    assert listing(tmp_path) == ["fresh.txt", "result.json"]


def test_writing_through_a_symlink_updates_its_target(tmp_path):
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    _io.write_text(link, "new")
    assert link.is_symlink() and target.read_text() == "new"


def test_a_missing_folder_is_named(tmp_path):
    with pytest.raises(OSError, match=r"cannot write .*nowhere/r\.json: the folder .*nowhere does not exist"):
        _io.check_writable(tmp_path / "nowhere" / "r.json")
    with pytest.raises(OSError, match=r"cannot write .*nowhere/r\.json"):
        _io.write_text(tmp_path / "nowhere" / "r.json", "x")


def test_result_save_is_atomic_and_refuses_unknown_formats(tmp_path, emps):
    r = didim.identify(emps, "rigid", "idim-ls", offset=True)
    r.save(tmp_path / "r.json")
    assert json.loads((tmp_path / "r.json").read_text())["params"]["M"] == pytest.approx(95.1089, abs=1e-4)
    r.save(tmp_path / "r.txt")
    assert "idim-ls identification of the rigid model" in (tmp_path / "r.txt").read_text()
    with pytest.raises(didim.DataError, match=r"cannot save a result as '\.csv': use \.json or \.txt"):
        r.save(tmp_path / "r.csv")
    assert listing(tmp_path) == ["r.json", "r.txt"]


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "didim", *args], capture_output=True, text=True, timeout=600)


def test_the_cli_never_modifies_its_input(tmp_path, emps_path):
    before = (sha256(emps_path), os.stat(emps_path).st_mtime_ns)
    p = _cli("identify", str(emps_path), "--method", "didim", "--apm", "78", "--json", str(tmp_path / "r.json"),
             "--plot", str(tmp_path / "fit.png"), "--quiet")
    assert p.returncode == 0, p.stderr
    assert (sha256(emps_path), os.stat(emps_path).st_mtime_ns) == before
    assert listing(tmp_path) == ["fit.png", "r.json"]


def test_the_api_never_modifies_its_input(tmp_path, emps_path):
    before = sha256(emps_path)
    rec = didim.load_mat(emps_path)
    didim.identify(rec, "rigid", "didim", apM=78.0, max_iter=2)
    assert sha256(emps_path) == before
    with pytest.raises(ValueError, match="read-only"):
        rec.qm[0] = 1.0  # the record's arrays cannot be changed in place either


def test_the_cli_refuses_to_write_over_its_input_and_fails_before_the_work(tmp_path, emps_path):
    copy = tmp_path / "in.mat"
    copy.write_bytes(emps_path.read_bytes())
    before = sha256(copy)
    p = _cli("identify", str(copy), "--json", str(copy))
    assert p.returncode == 2 and "is the input" in p.stderr and sha256(copy) == before
    p = _cli("identify", str(copy), "--json", str(tmp_path / "missing" / "r.json"), "--plot", str(tmp_path / "f.png"))
    assert p.returncode == 2 and "the folder" in p.stderr and "does not exist" in p.stderr
    assert "identification" not in p.stdout  # failed before identifying
    assert listing(tmp_path) == ["in.mat"]
    p = _cli("identify", str(copy), "--json", str(tmp_path / "a.json"), "--plot", str(tmp_path / "a.json"))
    assert p.returncode == 2 and "are the same file" in p.stderr


def test_a_failed_cli_run_keeps_the_previous_outputs(tmp_path, emps_path):
    out = tmp_path / "r.json"
    out.write_text('{"previous": 1}\n')
    p = _cli("identify", str(emps_path), "--method", "didim", "--apm", "-1", "--json", str(out))
    assert p.returncode == 2
    assert out.read_text() == '{"previous": 1}\n' and listing(tmp_path) == ["r.json"]


def test_outputs_hold_no_nan_tokens(tmp_path):
    r = didim.IdentificationResult(model="rigid", method="x", params={"M": 1.0}, std={"M": float("nan")},
                                   rel_std_pct={"M": float("inf")}, relative_error=float("nan"), iterations=0,
                                   simulations=0, elapsed_s=0.0, options={"v": np.float64("nan")})
    r.save(tmp_path / "r.json")
    d = json.loads((tmp_path / "r.json").read_text(), parse_constant=lambda c: pytest.fail(f"non-JSON token {c}"))
    assert d["std"]["M"] is None and d["rel_std_pct"]["M"] is None


def test_the_cli_checks_the_figure_format_before_the_work(tmp_path, emps_path):
    p = _cli("identify", str(emps_path), "--plot", str(tmp_path / "fit.docx"))
    assert p.returncode == 2 and "cannot write a figure as .docx" in p.stderr and ".png" in p.stderr
    assert "identification" not in p.stdout and listing(tmp_path) == []


@pytest.mark.parametrize("unnamed", [True, False])
def test_the_unnamed_file_and_both_fallbacks_write_the_same_file(tmp_path, monkeypatch, unnamed):
    # Linux writes into an O_TMPFILE file that has no name until it is complete (a SIGKILL then leaves nothing);
    # where the link is refused, or there is no O_TMPFILE, a named temporary file does the same job
    if unnamed:
        def refuse(fd, name):
            raise OSError(18, "Invalid cross-device link")
        monkeypatch.setattr(_io, "_link_fd", refuse)
    else:
        monkeypatch.setattr(_io, "_unnamed_file", lambda folder: None)
    target = tmp_path / "out.json"
    target.write_text("old")
    os.chmod(target, 0o640)
    _io.write_text(target, '{"new": true}\n')
    assert target.read_text() == '{"new": true}\n'
    assert oct(os.stat(target).st_mode & 0o777) == oct(0o640)
    assert sorted(os.listdir(tmp_path)) == ["out.json"]
