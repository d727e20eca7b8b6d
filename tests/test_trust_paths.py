"""Issue 13's data-loss and hang classes, at their root: one guard for every command's outputs, inputs that must be
regular files, and a writer that never renames over a device. Special files are made in a temporary folder (a FIFO,
a read-only file); no test writes to a real device."""

import os
import shutil
import stat
import subprocess
import sys

import pytest

import didim
from didim.formats import _io


def run_cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "didim.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture
def record(tmp_path, emps_path):
    p = tmp_path / "x.mat"
    shutil.copy(emps_path, p)
    return p


@pytest.mark.parametrize("argv", [
    lambda r: ["doctor", r, "--json", r],
    lambda r: ["doctor", r, "--html", f"{r.parent}/./{r.name}"],
    lambda r: ["doctor", r, "--validate", r.parent / "v.mat", "--json", r.parent / "v.mat"],
    lambda r: ["doctor", r, "--json", r.parent / "same.out", "--html", r.parent / "same.out"],
    lambda r: ["sweep", r, "--grid", "apM=50,100", "--json", r],
    lambda r: ["identify", r, "--json", r],
    lambda r: ["simulate", r, r.parent / "res.json", "--json", r.parent / "res.json"],
])
def test_no_command_overwrites_an_input_or_writes_one_file_twice(record, argv):
    shutil.copy(record, record.parent / "v.mat")
    (record.parent / "res.json").write_text("{}")
    before = {p: p.read_bytes() for p in record.parent.iterdir()}
    out = run_cli(*argv(record))
    assert out.returncode == 2, out.stdout + out.stderr
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert {p: p.read_bytes() for p in record.parent.iterdir() if p in before} == before
    assert not [p for p in record.parent.iterdir() if p.name.startswith(".") and ".tmp" in p.name]


def test_a_hard_link_or_symlink_to_the_input_is_refused(record):
    os.link(record, record.parent / "hard.json")
    os.symlink(record, record.parent / "soft.json")
    for out in ("hard.json", "soft.json"):
        r = run_cli("identify", record, "--json", record.parent / out)
        assert r.returncode == 2 and "is the input" in r.stderr


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_as_input_is_refused_without_blocking(tmp_path, record):
    fifo = tmp_path / "in.mat"
    os.mkfifo(fifo)
    with pytest.raises(didim.DataError, match="FIFO"):
        didim.load_mat(fifo)
    r = run_cli("identify", fifo, timeout=60)
    assert r.returncode == 2 and "FIFO" in r.stderr
    r = run_cli("doctor", record, "--validate", fifo, timeout=60)
    assert r.returncode == 2 and "FIFO" in r.stderr
    with pytest.raises(didim.DataError, match="FIFO"):
        didim.load_result(fifo)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_a_fifo_as_output_is_refused_and_left_a_fifo(tmp_path, record):
    fifo = tmp_path / "out.json"
    os.mkfifo(fifo)
    r = run_cli("identify", record, "--json", fifo, timeout=60)
    assert r.returncode == 2 and "FIFO" in r.stderr
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    with pytest.raises(didim.DataError, match="FIFO"):
        _io.write_text(fifo, "x")
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_device_is_written_in_place_never_renamed_over(tmp_path, monkeypatch):
    """A character device (like /dev/null) is simulated by a regular file the writer is told is one: the content goes
    into it through open(), and no temporary file is renamed over it."""
    target = tmp_path / "dev"
    target.write_text("old")
    inode = os.stat(target).st_ino
    monkeypatch.setattr(_io, "_special", lambda t: "device" if os.path.realpath(t) == str(target) else "")
    _io.write_text(target, "new content")
    assert target.read_text() == "new content" and os.stat(target).st_ino == inode
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dev"]


def test_bad_input_paths_are_data_errors(tmp_path):
    for bad in (None, 3.5):
        with pytest.raises(didim.DataError, match="path"):
            didim.load_mat(bad)
    with pytest.raises(didim.DataError, match="no such file"):
        didim.load_mat(os.fsencode(tmp_path / "missing.mat"))
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(didim.DataError, match="loop of symbolic links"):
        didim.load_mat(tmp_path / "a")
    with pytest.raises(didim.DataError, match="folder"):
        didim.load_mat(tmp_path)
