"""The grid validation's standalone C program (issue 9 point 5): built from generated/ (which a
test of tests/test_codegen.py keeps equal to a fresh generation), linking only libc and libm, and
agreeing with the Python run of validation_grid through the terrain engine step by step
(measured on the development machine: identical to the last bit; the tolerances allow another
compiler's rounding)."""

import shutil
import subprocess

import numpy as np
import pytest

import symtrack
from symtrack.toolchain import find_compiler

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler")


@pytest.fixture(scope="module")
def both():
    from symtrack.codegen import grid_standalone

    binary = grid_standalone.build()
    rows = grid_standalone.run(binary)
    res = symtrack.simulate("validation_grid")
    return binary, rows, res.runs[0]


def test_the_standalone_grid_program_agrees_with_python(both):
    _, rows, run = both
    X, Y = run.X[1:], run.Y[1:]  # the steps after the start
    assert rows.shape == (X.shape[0], 1 + X.shape[1] + Y.shape[1])
    assert np.allclose(rows[:, 0], run.t[1:], rtol=0, atol=1e-12)
    assert np.max(np.abs(rows[:, 1:1 + X.shape[1]] - X) / np.maximum(1.0, np.abs(X))) < 1e-9
    assert np.max(np.abs(rows[:, 1 + X.shape[1]:] - Y) / np.maximum(1.0, np.abs(Y))) < 1e-7
    # it stopped where Python stopped: 20 m after the idle event
    assert run.stopped_by == "distance" and rows[-1, 0] == pytest.approx(run.t[-1], abs=1e-12)


def test_the_standalone_grid_program_links_only_libc_and_libm(both):
    binary = both[0]
    if shutil.which("ldd") is None:
        pytest.skip("no ldd")
    out = subprocess.run(["ldd", str(binary)], capture_output=True, text=True).stdout
    libs = {line.split()[0] for line in out.splitlines() if "=>" in line}
    assert libs <= {"libm.so.6", "libc.so.6"}, out
