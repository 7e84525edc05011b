"""The one compile-and-cache API: C sources -> a shared library or a program in a hash-keyed cache.

Every compiled artefact of symtrack goes through :func:`build`: the model libraries
(:mod:`symtrack.native.cache`), the terrain engine (:mod:`symtrack.integrators.engine.kernel`), the grid
Rosenbrock integrator (:mod:`symtrack.integrators.grid_rosenbrock`), the MPC's functions
(:mod:`symtrack.control.solver_cache`) and the standalone programs (:mod:`symtrack.codegen`). A caller
describes one artefact with a :class:`BuildSpec` (what identifies it: its key, made with
:func:`digest`; how to get its sources, called only when it is missing; how to compile them) and gets
its path. This module alone owns:

- the cache's location, :func:`cache_root`: ``$SYMTRACK_CACHE`` or ``~/.cache/symtrack``; a folder that
  cannot be written (read-only, a file, under a file) is replaced, with a warning, by a private temporary
  cache removed when the process exits;
- the entry's folder, ``<root>[/<group>]/<kind>-<key[:digits]><suffix>/``, and the artefact in it;
- the lock: processes that build one entry at once (parallel test workers, sweep workers) take
  turns on ``<entry>/.lock`` (``flock``, released when its holder exits or dies): the first
  compiles, the others find its artefact and compile nothing;
- the atomic write: the sources are written and compiled in a temporary folder ``<entry>/.build-*``
  and the artefact is renamed into place, so that an interrupted build (Ctrl-C, a killed worker)
  leaves no half-written library; a temporary folder a killed build left behind is removed by the
  next build of the entry;
- the check: the artefact's size and SHA-256 are recorded beside it (``<artefact>.sha256.json``) before
  it is renamed into place and checked before it is handed out (once per process and artefact); a
  damaged artefact (truncated, overwritten, no record) is rebuilt instead of being loaded (a damaged
  shared library crashes the loader: "Bus error");
- the compiler lookup (``$CC``, ``cc``, ``gcc``) and its messages: :func:`compiler` for callers that
  can fall back on CasADi's interpreter (a warning once; an error with :func:`set_require_compiled`,
  ``--require-compiled`` or ``SYMTRACK_REQUIRE_COMPILED=1``), :func:`require_compiler` and
  :func:`build` for those that cannot (an error that names what was being built);
- the log: ``compiling <what> (first run; cached in <entry>) ...`` and ``compiled <what> in <s> s``
  at INFO on the ``symtrack.toolchain`` logger (a user who waits minutes for the compiler is told why),
  and :data:`builds`, every compilation of this process.

A cache hit costs a ``stat`` and, the first time in a process, reading and hashing the artefact: no
lock, no source generation, no compiler lookup.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import hashlib
import json
import logging
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path

import casadi as ca

from ..foundations import caches
from ..foundations.errors import SimulationError

__all__ = ["BIG_FILE_BYTES", "CFLAGS_BIG", "CFLAGS_NATIVE", "CFLAGS_SHARED", "CFLAGS_SMALL", "NO_COMPILER",
           "OPT_LEVEL_ENV", "TUNED_OPT_LEVEL_ENV", "opt_level",
           "BuildSpec", "Built", "LockBusy", "build", "builds", "cache_root", "casadi_tag", "compiled_required",
           "compiler", "digest", "file_lock", "find_compiler", "native_cflags", "require_compiler",
           "set_require_compiled"]

log = logging.getLogger("symtrack.toolchain")

# the large straight-line Jacobian files take 2x longer to compile at -O2 for little gain
BIG_FILE_BYTES = 600_000
CFLAGS_SMALL = ("-O2",)
CFLAGS_BIG = ("-O1",)
# Only the CASADI_SYMBOL_EXPORT functions are exported: the generated helpers then are not
# interposable, which lets the compiler call them directly (-fPIC alone made the integrator
# 20 % slower than in the standalone program).
CFLAGS_SHARED = ("-fPIC", "-fvisibility=hidden", "-DGCC_HASCLASSVISIBILITY")
# The hot kernels' flags (the terrain engine and tests/test_subsoil.py's check library): -O3
# -march=native lets gcc turn subsoil.h's loops over the loaded cells into SIMD code with gathers;
# -ffp-contract=off forbids fused multiply-adds, so every sum is rounded as in the scalar code and the
# figures do not depend on the machine's instruction set (tests/test_subsoil.py: the SIMD block equals
# the scalar lookup bit for bit; validation_grid's states, rut and stress fields are bit for bit those of
# -O2); -fno-math-errno only drops errno writes (sqrt inlined, the same correctly rounded result).
# Measured on validation_grid with the shear law (docs/terrain.md, "Speed").
# -mprefer-vector-width=256: 256-bit vectors even where the processor has 512-bit ones (gcc's own
# default when it tunes for Intel's AVX-512 processors; gcc 12 tunes AMD's Zen 4 as znver3 and
# then used 512-bit gathers, which cost the subsoil stress 38 instead of 33 us per macro step there:
# docs/terrain.md, "Speed"); the same operations per lane, so the same bits.
CFLAGS_NATIVE = ("-O3", "-march=native", "-mprefer-vector-width=256", "-ffp-contract=off", "-fno-math-errno")
MAX_JOBS = 2  # compilers at a time (2-core machines)
# $SYMTRACK_OPT_LEVEL (0, 1, 2 or 3; unset: the flags above): the optimisation level of every artefact
# that is not ``tuned`` (the tuned ones are the hot kernels whose speed or vector code is the point: the
# terrain engine, the SIMD check library). The test suite sets 0 (tests/conftest.py): gcc then spends a
# seventh of its -O2 time on the large generated Jacobians (9.4 s -> 1.3 s of CPU for the compiled
# Rosenbrock), and the arithmetic is the same (no fast-math, no contraction at any level on x86-64).
# The level enters the artefacts' folder names, so the two builds never share a cache entry.
OPT_LEVEL_ENV = "SYMTRACK_OPT_LEVEL"
# $SYMTRACK_TUNED_OPT_LEVEL (0-3; unset: their own flags): the same for the tuned artefacts, keeping their
# other flags (-march=native, no contraction: the same arithmetic). The test suite sets 1
# (tests/conftest.py): the terrain engine then compiles in a third of gcc's time at -O3 (10.0 -> 3.5 s
# of CPU for validation_grid's) and runs validation_grid in the same time (0.33 s); at -O0 it would
# compile in 1.4 s but run 1.7 x slower. A test of the vector code itself (the SIMD check) clears it.
TUNED_OPT_LEVEL_ENV = "SYMTRACK_TUNED_OPT_LEVEL"
NO_COMPILER = "no C compiler found (looked for $CC, cc, gcc)"

_require = os.environ.get("SYMTRACK_REQUIRE_COMPILED", "") not in ("", "0")
_warned_no_compiler = False


@dataclasses.dataclass(frozen=True)
class Built:
    """One compilation of this process: its kind, its description, the artefact, the seconds."""

    kind: str
    what: str
    path: Path
    seconds: float


# every compilation of this process, in order (the tests and the MPC's solver cache read it)
builds: list[Built] = []


@dataclasses.dataclass(frozen=True)
class BuildSpec:
    """One cached artefact and how to build it.

    Parameters
    ----------
    kind : str
        The entry's folder name before its key: ``engine``, ``grid``, ``homogeneous_ode``, ...
    key : str
        The hexadecimal :func:`digest` of everything the artefact depends on (the serialised
        Functions or the sources, the flags where they vary, :func:`casadi_tag`). Cheap to compute:
        the sources themselves are made only on a miss.
    output : str
        The artefact's file name in the entry: ``libX.so`` or a program's name.
    sources : callable
        ``sources() -> {file name: bytes}``: every file the compilation needs (the .c units and what
        they include), written flat into the build folder; called only when the artefact is missing.
    what : str
        What is being built, for the log and the errors ("the terrain engine").
    units : tuple of str, optional
        The files compiled (default: every ``.c`` of the sources; a ``.c`` that another includes is
        left out by naming the units).
    cflags : tuple of str, optional
        The compile flags of every unit (default: :data:`CFLAGS_SMALL`, :data:`CFLAGS_BIG` for a
        unit above :data:`BIG_FILE_BYTES`).
    shared : bool
        A shared library (``shared_cflags`` added to every unit, linked with ``-shared``) or a program.
    shared_cflags : tuple of str
        The flags a shared library's units get besides ``cflags``.
    one_command : bool
        Compile and link in one compiler call (default: one call per unit, at most :data:`MAX_JOBS`
        at a time, largest first, then one link call).
    digits : int
        The hexadecimal digits of the key in the folder name.
    suffix : str
        Appended to the folder name (a layout version, ``-b2``).
    group : str
        A sub-folder of the cache root (``mpc``).
    root : Path, optional
        A folder that replaces the cache root and the group (the MPC's ``jit_dir``).
    """

    kind: str
    key: str
    output: str
    sources: Callable[[], Mapping[str, bytes]]
    what: str
    units: tuple[str, ...] | None = None
    cflags: tuple[str, ...] | None = None
    shared: bool = True
    shared_cflags: tuple[str, ...] = CFLAGS_SHARED
    one_command: bool = False
    digits: int = 16
    suffix: str = ""
    group: str = ""
    root: Path | None = None
    tuned: bool = False

    @property
    def folder(self) -> Path:
        """The entry's folder (``-O<n>`` after the key when :func:`opt_level` overrides the flags)."""
        base = Path(self.root) if self.root is not None else (cache_root() / self.group if self.group
                                                              else cache_root())
        n = opt_level(tuned=self.tuned)
        level = "" if n is None else f"-O{n}"
        return base / f"{self.kind}-{self.key[:self.digits]}{self.suffix}{level}"

    @property
    def path(self) -> Path:
        """The artefact's path (it exists once built)."""
        return self.folder / self.output


_roots: dict[Path, Path] = {}  # the cache folder asked for -> the one used (itself, or a private one)


def cache_root() -> Path:
    """The cache's folder: ``$SYMTRACK_CACHE`` or ``~/.cache/symtrack``, created; when it cannot be
    written (read-only, a file, under a file) a private temporary folder instead, with a warning (once
    per process and folder; removed when the process exits)."""
    env = os.environ.get("SYMTRACK_CACHE")
    want = Path(env).expanduser() if env else Path.home() / ".cache" / "symtrack"
    if want not in _roots:
        _roots[want] = _usable(want, "SYMTRACK_CACHE" if env else "the default cache folder")
    return _roots[want]


def _usable(want: Path, what: str) -> Path:
    try:
        want.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".probe-", dir=want)
        os.close(fd)
        os.unlink(probe)
        return want
    except OSError as err:
        problem = "a file, not a folder" if want.exists() and not want.is_dir() else err.strerror or str(err)
    private = Path(tempfile.mkdtemp(prefix="symtrack-cache-"))
    atexit.register(shutil.rmtree, private, ignore_errors=True)
    log.warning("%s %s cannot be written (%s): compiling into a private temporary cache %s instead, removed at "
                "exit (set SYMTRACK_CACHE to a writable folder to keep the compiled code)", what, want, problem,
                private)
    return private


def digest(*parts: bytes | str) -> str:
    """SHA-256 (hexadecimal) of the parts in order (a str as UTF-8): the key of a :class:`BuildSpec`."""
    h = hashlib.sha256()
    for part in parts:
        h.update(part.encode() if isinstance(part, str) else part)
    return h.hexdigest()


def casadi_tag(build_version: int) -> str:
    """``<CasADi version>/<build_version>``: the key part that rebuilds an artefact when CasADi's
    generated code or the caller's layout (its build version) changes."""
    return f"{ca.__version__}/{build_version}"


def set_require_compiled(flag: bool = True) -> None:
    """Make a missing C compiler an error in :func:`compiler` instead of a fallback to the interpreter."""
    global _require
    _require = bool(flag)


def compiled_required() -> bool:
    """Whether compiled code is required (:func:`set_require_compiled`, ``SYMTRACK_REQUIRE_COMPILED``)."""
    return _require


def find_compiler() -> str | None:
    """The C compiler's path: ``$CC``, else ``cc``, else ``gcc``; None when there is none."""
    for cc in (os.environ.get("CC"), "cc", "gcc"):
        if cc and shutil.which(cc):
            return shutil.which(cc)
    return None


def compiler() -> str | None:
    """The C compiler for a caller that can run on CasADi's interpreter instead: None after saying
    once that there is none (a SimulationError when compiled code is required)."""
    global _warned_no_compiler
    cc = find_compiler()
    if cc is None:
        if _require:
            raise SimulationError(f"{NO_COMPILER} and compiled code is required (--require-compiled); install "
                                  "gcc (or set $CC) or drop --require-compiled")
        if not _warned_no_compiler:
            log.warning("%s: running the generated functions on CasADi's interpreter instead (slower)",
                        NO_COMPILER)
            _warned_no_compiler = True
    return cc


_native = caches.cache("compiler_flags", 4)  # per compiler (symtrack.foundations.caches)


def native_cflags(cc: str) -> tuple[tuple[str, ...], str]:
    """``(flags, tag)`` of the hot kernels for compiler ``cc``: :data:`CFLAGS_NATIVE` when ``cc`` takes
    them, else :data:`CFLAGS_SMALL` with ``-ffp-contract=off``. ``tag`` (for the artefact's key): a
    digest of the compiler's predefined macros under those flags, i.e. of the instruction sets
    ``-march=native`` chose, so that a cache shared by machines of different processors (a cluster's
    home folder) never hands one machine another's code. Probed once per compiler and process."""
    hit = _native.get(cc)
    if hit is None:
        flags: tuple[str, ...] = CFLAGS_NATIVE
        try:
            res = subprocess.run([cc, *flags, "-dM", "-E", "-x", "c", os.devnull], stdout=subprocess.PIPE,
                                 stderr=subprocess.DEVNULL, timeout=60)
            ok = res.returncode == 0
        except (OSError, subprocess.SubprocessError):
            ok = False
        if not ok:
            flags = (*CFLAGS_SMALL, "-ffp-contract=off")
            res = subprocess.run([cc, *flags, "-dM", "-E", "-x", "c", os.devnull], stdout=subprocess.PIPE,
                                 stderr=subprocess.DEVNULL, timeout=60)
        macros = b"\n".join(sorted(res.stdout.splitlines()))
        hit = _native.put(cc, (flags, digest(" ".join(flags), macros)))
    return hit


def require_compiler(what: str) -> str:
    """The C compiler; a SimulationError naming ``what`` cannot be built when there is none."""
    cc = find_compiler()
    if cc is None:
        raise SimulationError(f"{NO_COMPILER}: cannot build {what}; install gcc (or set $CC)")
    return cc


def build(spec: BuildSpec, cc: str | None = None) -> Path:
    """The path of ``spec``'s artefact, compiled into the cache first when it is missing.

    Parameters
    ----------
    spec : BuildSpec
        The artefact.
    cc : str, optional
        The compiler (default: :func:`require_compiler`, looked up only on a miss).

    Returns
    -------
    Path
        The artefact (a shared library to load, or a program to run).

    Raises
    ------
    SimulationError
        No C compiler; the sources or the compiler failed (the compiler's output in the message).
    """
    out = spec.path
    if out.exists() and _intact(out) is None:
        return out
    cc = cc or require_compiler(spec.what)
    out.parent.mkdir(parents=True, exist_ok=True)
    with _entry_lock(out.parent) as locked:
        damage = _intact(out) if out.exists() else None
        if out.exists() and damage is None:  # built by another process while this one waited for the lock
            log.info("%s: built by another process meanwhile (%s)", spec.what, out.parent)
            return out
        if damage is not None:
            (log.info if damage == NO_RECORD else log.warning)(
                "%s: the cached %s is not used (%s); building it again", spec.what, out, damage)
            out.unlink()
        if locked:  # no other build of the entry runs: a temporary folder is a killed build's
            for stale in out.parent.glob(".build-*"):
                shutil.rmtree(stale, ignore_errors=True)
        t0 = time.perf_counter()
        log.info("compiling %s (first run; cached in %s) ...", spec.what, out.parent)
        _compile(spec, dict(spec.sources()), out, cc)
        seconds = time.perf_counter() - t0
        builds.append(Built(spec.kind, spec.what, out, seconds))
        log.info("compiled %s in %.1f s", spec.what, seconds)
        _log_build(spec, seconds)
    return out


def _log_build(spec: BuildSpec, seconds: float) -> None:
    """One JSON line per compilation appended to ``$SYMTRACK_BUILD_LOG`` when it is set (the
    kind, what, seconds and the test that asked for it): how the test suite's time splits between
    compiling and running."""
    dest = os.environ.get("SYMTRACK_BUILD_LOG")
    if not dest:
        return
    row = {"kind": spec.kind, "what": spec.what, "seconds": round(seconds, 2),
           "test": os.environ.get("PYTEST_CURRENT_TEST", "").rsplit(" ", 1)[0], "pid": os.getpid()}
    with open(dest, "a", encoding="utf-8") as f:  # one short write per line: lines do not interleave
        f.write(json.dumps(row) + "\n")


NO_RECORD = "no size and SHA-256 recorded beside it (built by an older symtrack)"
# artefacts found intact in this process: (inode, size, mtime) (symtrack.foundations.caches)
_checked = caches.cache("artefact_checks", 1024)


def _record_path(out: Path) -> Path:
    """The record of an artefact's size and SHA-256: ``<artefact>.sha256.json`` beside it."""
    return out.with_name(out.name + ".sha256.json")


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _intact(out: Path) -> str | None:
    """None when the artefact ``out`` has the size and SHA-256 recorded when it was written; else what is
    wrong (checked once per process while the file stays the same)."""
    try:
        st = out.stat()
    except OSError as err:
        return f"cannot read it: {err.strerror or err}"
    stamp = (st.st_ino, st.st_size, st.st_mtime_ns)
    if _checked.get(out) == stamp:
        return None
    try:
        rec = json.loads(_record_path(out).read_text())
        size, sha = int(rec["size_bytes"]), str(rec["sha256"])
    except FileNotFoundError:
        return NO_RECORD
    except (OSError, ValueError, KeyError, TypeError) as err:
        return f"its record {_record_path(out).name} is unreadable ({err})"
    if st.st_size != size:
        return f"{st.st_size} bytes, {size} recorded: damaged"
    try:
        if _sha256_file(out) != sha:
            return "its SHA-256 differs from the one recorded: damaged"
    except OSError as err:
        return f"cannot read it: {err.strerror or err}"
    _checked.put(out, stamp)
    return None


@contextlib.contextmanager
def _entry_lock(folder: Path):
    """An exclusive lock on ``folder/.lock`` (flock; released when the holder exits or dies); yields
    whether it is held: no lock where flock is missing (the rename alone keeps the artefact whole)."""
    with file_lock(folder / ".lock") as held:
        yield held is not False


class LockBusy(Exception):
    """:func:`file_lock` with ``wait=False`` found the lock held; ``holder`` is what the holder wrote
    into the lock file (its process id), or ""."""

    def __init__(self, path: Path, holder: str):
        super().__init__(f"{path} is held by process {holder or '(unknown)'}")
        self.path, self.holder = path, holder


@contextlib.contextmanager
def file_lock(path, wait: bool = True, remove: bool = False):
    """An exclusive lock on the file ``path`` (created if missing; ``flock``: released when the
    holder exits or dies, so a killed holder never leaves it taken). The holder writes its process
    id into the file. ``wait=False``: :class:`LockBusy` at once when another process holds it.
    ``remove``: the holder removes the file when it lets go (on any exit but a kill; a file a killed
    holder left is taken over by the next one); a process that locked a file its holder had just removed
    sees it is gone and locks the path's new file. Yields the process id written, or False where flock is
    missing (not POSIX: no lock). The one lock of symtrack (the cache's entries, terrain files, run folders)."""
    try:
        import fcntl
    except ImportError:  # not POSIX
        yield False
        return
    path = Path(path)
    while True:
        fh = open(path, "a+b")  # noqa: SIM115 (closed below)
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read(64).decode(errors="replace").strip()
            fh.close()
            raise LockBusy(path, holder) from None
        except BaseException:
            fh.close()
            raise
        if not remove:
            break
        try:  # still the file at ``path`` (not one its last holder removed meanwhile)?
            if os.path.samestat(os.fstat(fh.fileno()), os.stat(path)):
                break
        except FileNotFoundError:
            pass
        fh.close()
    with fh:
        try:
            fh.seek(0)
            fh.truncate()
            fh.write(str(os.getpid()).encode())
            fh.flush()
            yield os.getpid()
        finally:
            if remove:
                with contextlib.suppress(OSError):
                    path.unlink()
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def opt_level(tuned: bool = False) -> int | None:
    """The optimisation level ``$SYMTRACK_OPT_LEVEL`` sets for the artefacts that are not tuned, or
    ``$SYMTRACK_TUNED_OPT_LEVEL`` for the tuned ones (None: unset, each artefact's own flags); a value
    other than 0-3 is a :class:`SimulationError`."""
    name = TUNED_OPT_LEVEL_ENV if tuned else OPT_LEVEL_ENV
    value = os.environ.get(name, "").strip()
    if not value:
        return None
    if value not in ("0", "1", "2", "3"):
        raise SimulationError(f"${name} = {value!r} is not one of 0, 1, 2, 3 (or unset: the artefacts' own flags)")
    return int(value)


def _unit_flags(spec: BuildSpec, size: int) -> tuple[str, ...]:
    flags = spec.cflags if spec.cflags is not None else (CFLAGS_BIG if size > BIG_FILE_BYTES else CFLAGS_SMALL)
    level = opt_level(tuned=spec.tuned)
    if level is not None:
        flags = tuple(f"-O{level}" if f.startswith("-O") else f for f in flags)
        flags = flags if f"-O{level}" in flags else (f"-O{level}", *flags)
    return (*flags, *spec.shared_cflags) if spec.shared else tuple(flags)


def _run(cmd: list[str], cwd: Path, what: str, cc: str) -> None:
    res = subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    if res.returncode != 0:
        raise SimulationError(f"building {what} failed ({cc}):\n{' '.join(cmd)}\n"
                              f"{res.stdout.decode(errors='replace')[-2000:]}")


def _compile(spec: BuildSpec, sources: dict[str, bytes], out: Path, cc: str) -> None:
    """Write the sources into a temporary folder beside ``out``, compile them, rename the result to ``out``."""
    work = Path(tempfile.mkdtemp(prefix=".build-", dir=out.parent))
    jobs: list[tuple[str, subprocess.Popen]] = []
    try:
        for name, data in sources.items():
            (work / name).write_bytes(data)
        units = list(spec.units) if spec.units is not None else sorted(n for n in sources if n.endswith(".c"))
        missing = [u for u in units if u not in sources]
        if missing or not units:
            raise SimulationError(f"building {spec.what}: no source {', '.join(missing) or '(.c)'} among "
                                  f"{', '.join(sorted(sources))}")
        link = ["-shared"] if spec.shared else []
        tmp_out = work / out.name
        if spec.one_command:
            size = max(len(sources[u]) for u in units)
            _run([cc, *_unit_flags(spec, size), *link, *units, "-o", tmp_out.name, "-lm"], work, spec.what, cc)
        else:
            objs = []
            pending = sorted(units, key=lambda n: -len(sources[n]))  # biggest first
            while pending or jobs:
                while pending and len(jobs) < MAX_JOBS:
                    name = pending.pop(0)
                    obj = name.rsplit(".", 1)[0] + ".o"
                    cmd = [cc, *_unit_flags(spec, len(sources[name])), "-c", name, "-o", obj]
                    jobs.append((name, subprocess.Popen(cmd, cwd=work, stdout=subprocess.PIPE,
                                                        stderr=subprocess.STDOUT)))
                    objs.append(obj)
                name, proc = jobs.pop(0)
                text, _ = proc.communicate()
                if proc.returncode != 0:
                    raise SimulationError(f"compiling {name} of {spec.what} failed ({cc}):\n"
                                          f"{text.decode(errors='replace')[-2000:]}")
            _run([cc, *link, "-o", tmp_out.name, *objs, "-lm"], work, spec.what, cc)
        # the record first: an artefact in place always has one (a kill between the two: rebuilt next time)
        record = json.dumps({"size_bytes": tmp_out.stat().st_size, "sha256": _sha256_file(tmp_out)}) + "\n"
        (work / "record").write_text(record)
        os.replace(work / "record", _record_path(out))
        os.replace(tmp_out, out)
    finally:
        for _, proc in jobs:  # an error or an interrupt: no compiler outlives the build
            proc.kill()
            proc.wait()
        shutil.rmtree(work, ignore_errors=True)
