"""The terrain query (symtrack/terrain/query.py) and its C twin (symtrack/native/terrain_query.h)."""

import ctypes
from pathlib import Path

import numpy as np
import pytest

from symtrack.foundations.errors import SimulationError
from symtrack.terrain import query as Q
from symtrack.terrain.storage import Grid, Terrain
from symtrack.toolchain import BuildSpec, build, digest, find_compiler

NATIVE = Path(__file__).resolve().parent.parent / "symtrack" / "native"
GRID = Grid((-2.0, 1.0), 0.25, (12, 8))  # x in [-2, 1], y in [1, 3]


@pytest.fixture
def terrain():
    t = Terrain(GRID)
    rng = np.random.default_rng(5)
    t.z[:] = rng.uniform(0.0, 0.05, t.z.size)
    t.phase[:] = rng.integers(0, 3, t.z.size).astype(np.int8)
    return t


def test_shapes_and_values(terrain):
    q = Q.query(terrain, -1.9, 2.9)  # a scalar: cell (0, 7)
    assert q.cell.shape == () and int(q.cell) == 7 and q.normal.shape == (3,)
    assert float(q.height_m) == -terrain.z[7] and float(q.elevation_m) == 0.0
    x = np.linspace(-2.0, 1.0, 15).reshape(3, 5)  # both edges included: the upper edge is the last cell
    y = np.full((3, 5), 1.0)
    q = Q.query(terrain, x, y)
    assert q.cell.shape == (3, 5) and q.normal.shape == (3, 5, 3) and q.phase.shape == (3, 5)
    i = np.minimum(np.floor((x + 2.0) / 0.25), 11).astype(int)
    np.testing.assert_array_equal(q.cell, i * 8)
    np.testing.assert_array_equal(q.sinkage_m, terrain.z[i * 8])
    np.testing.assert_array_equal(q.height_m, -terrain.z[i * 8])  # flat field: elevation 0 minus sinkage
    np.testing.assert_array_equal(q.normal, np.broadcast_to([0.0, 0.0, 1.0], (3, 5, 3)))
    np.testing.assert_array_equal(q.phase, terrain.phase[i * 8])
    # broadcasting, and the two shortcuts
    assert Q.height_m(terrain, np.array([-1.0, 0.0]), 2.0).shape == (2,)
    assert Q.normal(terrain, [[-1.0], [0.0]], [1.5, 2.5]).shape == (2, 2, 3)
    # the cell under a cell centre is that cell, for every cell
    ii, jj = np.divmod(np.arange(GRID.n_cells), 8)
    np.testing.assert_array_equal(Q.cell_of(GRID, *GRID.centres(ii, jj)), np.arange(GRID.n_cells))


def test_outside_the_field(terrain):
    with pytest.raises(SimulationError, match=r"\(1\.5, 2\) m: outside the field, which spans x in \[-2, 1\] m "
                                              r"and y in \[1, 3\] m \(1 of 3 points outside\)"):
        Q.query(terrain, [0.0, 1.5, 0.5], [2.0, 2.0, 2.0])
    with pytest.raises(SimulationError, match="outside the field"):
        Q.height_m(terrain, 0.0, np.nan)
    q = Q.query(terrain, [0.0, 1.5, 0.0], [2.0, 2.0, 0.99], outside="nan")
    assert list(q.cell) == [int(Q.cell_of(GRID, 0.0, 2.0)), -1, -1] and list(q.phase[1:]) == [-1, -1]
    assert np.isfinite(q.height_m[0]) and np.all(np.isnan(q.height_m[1:])) and np.all(np.isnan(q.normal[1:]))
    with pytest.raises(ValueError, match="outside = 'clip'"):
        Q.query(terrain, 0.0, 2.0, outside="clip")


class _Field(ctypes.Structure):
    _fields_ = [("nx", ctypes.c_longlong), ("ny", ctypes.c_longlong), ("x0", ctypes.c_double),
                ("y0", ctypes.c_double), ("dx", ctypes.c_double), ("z", ctypes.c_void_p), ("phase", ctypes.c_void_p),
                ("elev", ctypes.c_void_p)]


@pytest.fixture(scope="module")
def clib():
    cc = find_compiler()
    if cc is None:
        pytest.skip("no C compiler")
    sources = {n: (NATIVE / n).read_bytes() for n in ("terrain_query.h", "terrain_query_check.c")}
    so = build(BuildSpec(kind="terrain_query_check", key=digest(*(sources[n] for n in sorted(sources))),
                         output="libterrain_query_check.so", sources=lambda: sources,
                         what="the terrain query's C check"), cc)
    lib = ctypes.CDLL(str(so))
    lib.terrain_query_many.restype = ctypes.c_longlong
    lib.terrain_query_many.argtypes = [ctypes.POINTER(_Field)] + [ctypes.c_void_p] * 2 + [ctypes.c_longlong] \
        + [ctypes.c_void_p] * 3
    return lib


@pytest.mark.parametrize("shaped", [False, True], ids=["flat", "elevation"])
def test_c_equals_numpy(clib, terrain, shaped):
    """The C query (terrain_query.h) and numpy's, bit for bit, on a flat field (elevation NULL) and on
    one with an elevation (random heights: the gradient's central and one-sided differences)."""
    if shaped:
        terrain.set_elevation(np.random.default_rng(3).uniform(-0.5, 0.5, terrain.z.size))
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.uniform(-2.3, 1.3, 4000), [-2.0, 1.0, 1.0, -1.75, np.nan]])
    y = np.concatenate([rng.uniform(0.8, 3.2, 4000), [1.0, 3.0, 2.0, 1.25, 2.0]])
    F = _Field(GRID.shape[0], GRID.shape[1], GRID.origin_m[0], GRID.origin_m[1], GRID.cell_m,
               terrain.z.ctypes.data, terrain.phase.ctypes.data,
               None if terrain.elevation is None else terrain.elevation.ctypes.data)
    n = x.size
    cell, phase, out = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.intc), np.zeros((n, 8))
    n_out = clib.terrain_query_many(ctypes.byref(F), x.ctypes.data, y.ctypes.data, n, cell.ctypes.data,
                                    phase.ctypes.data, out.ctypes.data)
    q = Q.query(terrain, x, y, outside="nan")
    assert n_out == np.count_nonzero(q.cell < 0) > 100  # the sample has points on every side of the field
    np.testing.assert_array_equal(cell, q.cell)
    np.testing.assert_array_equal(phase, q.phase)
    np.testing.assert_array_equal(out[:, 0], q.elevation_m)
    np.testing.assert_array_equal(out[:, 1], q.sinkage_m)
    np.testing.assert_array_equal(out[:, 2], q.height_m)
    np.testing.assert_array_equal(out[:, 3:6], q.normal)
    np.testing.assert_array_equal(out[:, 6:8], q.gradient)
    assert np.any(q.gradient[q.cell >= 0] != 0.0) == shaped
