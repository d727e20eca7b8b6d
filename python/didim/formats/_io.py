"""Every file didim writes (JSON, text tables, figures) goes through this module: the content is written to a temporary
file beside the target, flushed to disk, and renamed into place, so an interrupted or failed run leaves either the
old file or the complete new one, never a half-written file, and no temporary file behind."""

from __future__ import annotations

import errno
import math
import os
import shutil
import stat
import tempfile
from contextlib import contextmanager
from typing import Iterator

import numpy as np


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _target(path) -> str:
    """The file to replace: a symbolic link is followed, so the file it points to gets the new content."""
    return os.path.realpath(os.fspath(path))


def check_writable(path) -> None:
    """Raises OSError naming ``path`` when it cannot be written (missing folder, no permission, a folder), so that a
    long run fails before it starts rather than at the end."""
    target = _target(path)
    folder = os.path.dirname(target)
    if os.path.isdir(target):
        raise OSError(errno.EISDIR, f"cannot write {os.fspath(path)}: it is a folder")
    if not os.path.isdir(folder):
        if os.path.exists(folder):
            raise OSError(errno.ENOTDIR, f"cannot write {os.fspath(path)}: {folder} is a file, not a folder")
        raise OSError(errno.ENOENT, f"cannot write {os.fspath(path)}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OSError(errno.EACCES, f"cannot write {os.fspath(path)}: no permission to write in {folder}")


def jsonable(x):
    """Plain JSON types from numpy scalars and arrays, tuples and dicts; NaN and infinities become None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def _special(target: str) -> str:
    """'' for a regular or missing file, else what the existing ``target`` is (a device, a FIFO, a socket, a folder)."""
    try:
        mode = os.stat(target).st_mode
    except (FileNotFoundError, NotADirectoryError):
        return ""
    if stat.S_ISREG(mode):
        return ""
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "device"
    if stat.S_ISFIFO(mode):
        return "FIFO"
    if stat.S_ISSOCK(mode):
        return "socket"
    if stat.S_ISDIR(mode):
        return "folder"
    return "special file"


def check_input(path, what: str = "input file") -> str:
    """The path of an input that is a regular file; a FIFO (which would block), a device, a socket or a folder is a
    DataError naming it, before anything opens it."""
    from .._errors import DataError

    if isinstance(path, bytes):
        path = os.fsdecode(path)
    if not isinstance(path, (str, os.PathLike)):
        raise DataError(f"the {what} must be a path (str or os.PathLike), got {type(path).__name__}")
    shown = os.fspath(path)
    if "\0" in shown:
        raise DataError(f"the {what} path {shown!r} holds a NUL character: no file can have that name")
    if not shown:
        raise DataError(f"the {what} path is empty")
    try:
        mode = os.stat(shown).st_mode
    except FileNotFoundError:
        if os.path.islink(shown):
            raise DataError(f"{shown}: a symbolic link to a missing file") from None
        hint = ""
        if "shared/data" in shown.replace(os.sep, "/"):
            hint = (" (the examples read the data folder shared/data beside the checkout: clone next to it, or link "
                    "it there as the README's set-up says)")
        raise DataError(f"{shown}: no such file{hint}") from None
    except OSError as e:
        if e.errno == errno.ELOOP:
            raise DataError(f"{shown}: a loop of symbolic links") from None
        raise DataError(f"{shown}: cannot be read ({e.strerror or e})") from None
    if not stat.S_ISREG(mode):
        kind = _special(os.path.realpath(shown)) or "special file"
        raise DataError(f"{shown}: is a {kind}, not a regular file: give the path of the {what} itself")
    return shown


def check_outputs(inputs, outputs) -> None:
    """The one guard of every command, run before any work: an output is never an input (same file through any
    spelling, symbolic or hard link), two outputs are never the same file, an output is never a FIFO, a socket or a
    folder (a device such as /dev/null is written in place), and each output's folder is writable."""
    from .._errors import DataError

    def same(a: str, b: str) -> bool:
        try:
            return os.path.samefile(a, b)
        except OSError:
            return os.path.realpath(a) == os.path.realpath(b)

    if any(x is not None and os.fspath(x) == "" for x in outputs):
        raise DataError("an output path is empty: give a file name (or leave the option out)")
    ins = [os.fspath(x) for x in inputs if x]
    outs = [os.fspath(x) for x in outputs if x]
    for src in list(ins):  # a record's controller file beside it (NAME_controller.json) is an input too
        side = beside(src)
        if side is not None:
            ins.append(side)
    for i, out in enumerate(outs):
        for src in ins:
            if same(src, out):
                raise DataError(f"output {out} is the input {src}: choose another name (inputs are never modified)")
        for other in outs[:i]:
            if same(other, out):
                raise DataError(f"outputs {other} and {out} are the same file: choose two names")
        kind = _special(_target(out))
        if kind in ("FIFO", "socket", "folder", "special file"):
            raise DataError(f"output {out} is a {kind}: didim writes results to regular files (or a device such as "
                            "/dev/null); choose a file name")
        if kind != "device":
            try:
                check_writable(out)
            except OSError as e:
                raise DataError(e.strerror or str(e)) from None


@contextmanager
def atomic_path(path) -> Iterator[str]:
    """Yields a temporary path in the target's folder; when the block succeeds, the file written there is flushed to
    disk and replaces ``path`` (keeping the old file's permissions, or the default ones for a new file); when it
    fails, the temporary file is removed and ``path`` is untouched. A device (e.g. /dev/null) is never replaced: the
    content is written to it in place; a FIFO or a folder is refused."""
    shown = os.fspath(path)
    target = _target(path)
    kind = _special(target)
    if kind == "device":
        fd, tmp = tempfile.mkstemp(prefix=".didim.", suffix=".tmp")
        os.close(fd)
        try:
            yield tmp
            try:
                with open(tmp, "rb") as src, open(target, "wb") as dst:
                    shutil.copyfileobj(src, dst)
            except OSError as e:  # a full device (/dev/full), one that refuses writes: say which
                raise OSError(e.errno, f"cannot write {shown}: {e.strerror or e}") from None
        finally:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
        return
    if kind:
        from .._errors import DataError

        raise DataError(f"cannot write {shown}: it is a {kind}; choose a file name")
    folder = os.path.dirname(target)
    base, ext = os.path.splitext(os.path.basename(target))
    unnamed = _unnamed_file(folder)
    if unnamed is not None:
        # Linux: the content goes to a file with no name (O_TMPFILE), which the kernel frees if the process dies,
        # even by SIGKILL; it gets a name only once complete and flushed, for the two system calls that link and
        # rename it (instead of for the whole write and fsync)
        fd, tmp = unnamed
        named = None
        try:
            yield tmp
            os.fsync(fd)
            os.fchmod(fd, _mode_for(target))
            named = os.path.join(folder, f".{base}.{os.urandom(6).hex()}.tmp{ext}")
            try:
                _link_fd(fd, named)
            except OSError:  # a file system or a policy that refuses the link: a named copy, as without O_TMPFILE
                with open(tmp, "rb") as src, open(named, "xb") as dst:
                    shutil.copyfileobj(src, dst)
                    dst.flush()
                    os.fsync(dst.fileno())
                os.chmod(named, _mode_for(target))
            os.replace(named, target)
            named = None
            _fsync_folder(folder)
        finally:
            os.close(fd)
            if named is not None:
                try:
                    os.unlink(named)
                except FileNotFoundError:
                    pass
        return
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{base}.", suffix=f".tmp{ext}", dir=folder)
    except OSError as e:
        raise OSError(e.errno, f"cannot write {shown}: {e.strerror or e}") from None
    os.close(fd)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, _mode_for(target))
        os.replace(tmp, target)
        _fsync_folder(folder)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _mode_for(target: str) -> int:
    """The permissions of the file that replaces ``target``: the old file's, or the default ones for a new file."""
    try:
        return os.stat(target).st_mode & 0o7777
    except FileNotFoundError:
        return 0o666 & ~_umask()


def _link_fd(fd: int, name: str) -> None:
    """Gives the unnamed file ``fd`` the name ``name``: linkat of /proc/self/fd/N with AT_SYMLINK_FOLLOW (the
    unprivileged way; a directory fd makes os.link call linkat with that flag rather than link, which would try to
    link the /proc symlink itself)."""
    proc = os.open("/proc", os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        os.link(f"self/fd/{fd}", name, src_dir_fd=proc, follow_symlinks=True)
    finally:
        os.close(proc)


def _unnamed_file(folder: str):
    """An unnamed file in ``folder`` (O_TMPFILE) and a path that reopens it (/proc/self/fd), or None where the
    system or the file system has none (the caller then writes a named temporary file)."""
    flag = getattr(os, "O_TMPFILE", None)
    if flag is None or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        fd = os.open(folder or ".", flag | os.O_RDWR, 0o600)
    except OSError:
        return None
    path = f"/proc/self/fd/{fd}"
    if not os.path.exists(path):
        os.close(fd)
        return None
    return fd, path


def _fsync_folder(folder: str) -> None:
    """Makes the rename durable (best effort: not every platform can open a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_text(path, text: str) -> None:
    """Writes ``text`` to ``path`` atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)


def write_bytes(path, data: bytes) -> None:
    """Writes ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)


def save_figure(fig, path, **kw) -> None:
    """Saves a matplotlib figure atomically (format from the extension: png, svg, pdf, ...)."""
    fmt = os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, **kw)


def beside(path) -> "str | None":
    """The controller file beside a record, ``NAME_controller.json`` (or ``.toml``), if there is one; else the name
    cut at its last underscores, longest first: ``ur5_valid.csv`` and ``ur5_d4_train.csv`` read ``ur5_controller.json``
    (one controller for a robot's records, as the data folders have it; the controller check still compares it with
    each log)."""
    folder, name = os.path.split(os.path.splitext(os.fspath(path))[0])
    parts = name.split("_")
    for k in range(len(parts), 0, -1):
        stem = os.path.join(folder, "_".join(parts[:k]))
        for ext in (".json", ".toml"):
            if os.path.isfile(stem + "_controller" + ext):
                return stem + "_controller" + ext
    return None


__all__ = ["atomic_path", "check_writable", "check_input", "check_outputs", "write_text", "write_bytes", "save_figure", "beside"]
