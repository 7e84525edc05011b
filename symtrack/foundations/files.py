"""Atomic file writing: a temporary file in the same folder, fsync, then rename.

A reader never sees a half-written file: either the old content or the new. Every result file
of symtrack is written through these functions; a file replaced keeps its mode and, where the
process may set it, its owner and group (:func:`keep_mode`). :func:`check_output_folder` and
:func:`check_output_file` refuse, before any computation, an output that cannot be written.
:func:`read_text` reads a user's text file (a scenario, a preset, a boundary) as UTF-8, or raises an
error naming the file and what it holds instead (Latin-1, UTF-16, binary).
"""

from __future__ import annotations

import contextlib
import io
import os
import stat
import tempfile
import zipfile
from pathlib import Path

from .errors import ScenarioError

__all__ = ["DEFLATE_LEVEL", "atomic_write_bytes", "atomic_write_text", "check_output_file", "check_output_folder",
           "keep_mode", "npz_bytes", "read_text", "real_path", "write_new_file"]

_UMASK = os.umask(0)
os.umask(_UMASK)


# zlib's level of the .npz files symtrack writes (terrain files, pass counts). numpy's
# savez_compressed takes none and writes zlib's default, 6. Level 1, measured on season_4ha's
# 4-million-cell field after its four operations: 2.24 -> 1.26 s per terrain file, the file 8 %
# larger (docs/studies.md, "season_4ha"). The level changes the archive's bytes, never a value:
# np.load reads both the same.
DEFLATE_LEVEL = 1


def npz_bytes(**arrays) -> bytes:
    """The bytes of ``np.savez_compressed(buf, **arrays)`` at zlib level :data:`DEFLATE_LEVEL`: one
    ``NAME.npy`` member per array (``np.lib.format.write_array``, no pickles), zip deflate."""
    import numpy as np

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=DEFLATE_LEVEL) as zf:
        for name, value in arrays.items():
            with zf.open(name + ".npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
    return buf.getvalue()


def atomic_write_bytes(path: Path, data: bytes, before_rename=None) -> None:
    """Write ``data`` to ``path`` atomically (the folder is created if needed); ``before_rename()``, when
    given, is called between the temporary file's write and its rename (the commit's fault injection:
    symtrack/reports/run_files.py)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp creates 0600; results are ordinary files
        keep_mode(path, Path(tmp))  # a file replaced keeps its mode and owner
        if before_rename is not None:
            before_rename()
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_new_file(path: Path, data: bytes, mode_of: Path | None = None) -> None:
    """Write ``data`` into the new file ``path`` (an error if it exists; its folder is created if needed)
    and fsync it: a temporary file that is renamed later (a terrain file's, at a run's commit point). Its
    mode is that of ``mode_of`` when that file exists (the file it will replace), else an ordinary file's;
    a failed write removes it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(path, 0o666 & ~_UMASK)
        if mode_of is not None:
            keep_mode(mode_of, path)
    except BaseException:
        with contextlib.suppress(OSError):
            path.unlink()
        raise


def real_path(path) -> Path:
    """The file ``path`` names, symbolic links resolved (a missing file: its would-be real path). A
    terrain file given through a link is locked, written and replaced where it really is: the link
    stays a link and its target advances."""
    return Path(path).expanduser().resolve()


def keep_mode(old: Path, new: Path) -> None:
    """Give ``new`` (the temporary file about to replace ``old``) the mode of ``old`` and, where this
    process may set them (root, or a group it is in), its owner and group; nothing when ``old`` does not
    exist. A private terrain file (0600, 0640) stays private after a run replaced it."""
    try:
        st = os.stat(old)
    except OSError:
        return
    os.chmod(new, stat.S_IMODE(st.st_mode))
    cur = os.stat(new)
    if (cur.st_uid, cur.st_gid) != (st.st_uid, st.st_gid):
        try:
            os.chown(new, st.st_uid, st.st_gid)
        except OSError:  # not allowed: the owner stays this process's
            with contextlib.suppress(OSError):
                os.chown(new, -1, st.st_gid)


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write_bytes(path, text.encode())


def check_output_folder(path: str, option: str = "--out") -> Path:
    """Refuse, before any computation, an output folder that cannot be written."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ScenarioError(f"{option} {path!r} is an existing file, not a folder: give a folder name")
    probe = p
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ScenarioError(f"{option} {path!r}: {str(probe)!r} is a file, so the folder cannot be created")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise ScenarioError(f"{option} {path!r}: the folder {str(probe)!r} is not writable")
    return p


def check_output_file(path: str, option: str) -> Path:
    """Refuse, before any computation, an output file that cannot be written: a folder, in a folder that
    cannot be written, or an existing file that is read-only (no write permission for anybody, or not for
    this process), which a rename would otherwise replace."""
    p = Path(path)
    if p.is_dir():
        raise ScenarioError(f"{option} {path!r} is a folder: give a file name (e.g. out/terrain.npz)")
    check_output_folder(str(p.parent) if str(p.parent) else ".", option)
    try:
        mode = stat.S_IMODE(p.stat().st_mode)
    except OSError:
        return p  # a new file
    if not mode & 0o222 or not os.access(p, os.W_OK):
        raise ScenarioError(f"{option} {path!r} is read-only (mode {mode:04o}): symtrack does not replace a file its "
                            "owner protected; make it writable (chmod u+w) or give another file")
    return p


def read_text(path, what: str = "file", error: type[Exception] = ScenarioError) -> str:
    """The text of the UTF-8 file ``path`` (a UTF-8 byte-order mark dropped). A file that cannot be read
    or is not UTF-8 text raises ``error`` (a :class:`ScenarioError` unless told) with one line naming
    ``what`` and the file, and what it holds instead: UTF-16 (a byte-order mark, or a NUL in every other
    byte), binary data (NUL bytes, which no text file holds), or another 8-bit encoding such as Latin-1
    (the first byte that is not UTF-8, and its line)."""
    label = f"{what} {str(path)!r}"
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise error(f"{label}: cannot be read ({err.strerror or err})") from None
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    head = data[:4096]
    if data.startswith((b"\xff\xfe", b"\xfe\xff")) or (len(head) >= 2 and max(
            head[0::2].count(0), head[1::2].count(0)) >= 0.4 * len(head)):
        raise error(f"{label} is UTF-16 text; save it as UTF-8 text")
    if b"\x00" in data:
        raise error(f"{label} holds NUL bytes: binary data, not a text file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        raise error(f"{label} is not UTF-8 text (byte 0x{data[err.start]:02x} at offset {err.start}, line {line}: "
                    "Latin-1 or another 8-bit encoding?); save it as UTF-8 text") from None
