"""Numerical tables kept in the cache between processes (symtrack/toolchain/tables.py): a tyre's stress
table below its footprint, computed by one process and read by the next bit for bit; a damaged file
computed again; the key following the arguments and the code that computes the table."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from symtrack.region import fleet
from symtrack.soil import subsoil
from symtrack.toolchain import tables
from symtrack.vehicles import tyre as tyre_model

TYRE = tyre_model.Tyre(0.6, 1.6, 40.0, 160.0)
ARGS = (TYRE, 25.0, 120.0, 0.03, (0.2, 0.4), 5.0, 0.6, 0.03)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SYMTRACK_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "tables"


def _table(*args):
    return fleet.footprint_table_cached.__wrapped__(*args)  # past the process's own memory


def test_a_table_computed_once_is_read_back_bit_for_bit(cache, monkeypatch):
    c, tb = _table(*ARGS)
    files = list(cache.glob("footprint-*.npz"))
    assert len(files) == 1
    _, direct = tyre_model.footprint_table.__wrapped__(*ARGS)
    assert np.array_equal(tb.sz, direct.sz) and np.array_equal(tb.pm, direct.pm) and tb.step_m == direct.step_m
    assert tb.sz.shape[:2] == (21, 21) and tb.sz.shape[2] == 2 and c.force_kN.sum() == pytest.approx(25.0)

    def computes(*a, **k):
        raise AssertionError("the table was computed again instead of read from the cache")

    monkeypatch.setattr(fleet, "footprint_table", computes)
    c2, again = _table(*ARGS)
    assert np.array_equal(again.sz, tb.sz) and np.array_equal(again.pm, tb.pm)
    assert again.step_m == tb.step_m and again.depths_m == tb.depths_m and again.xi == tb.xi
    assert np.array_equal(c2.force_kN, c.force_kN)
    # another inflation is another table
    with pytest.raises(AssertionError, match="computed again"):
        _table(TYRE, 25.0, 140.0, *ARGS[3:])


def test_a_damaged_table_is_computed_again_and_replaced(cache, caplog):
    _, tb = _table(*ARGS)
    (path,) = cache.glob("footprint-*.npz")
    path.write_bytes(path.read_bytes()[:100])  # truncated
    with caplog.at_level(logging.WARNING, logger="symtrack.toolchain"):
        _, again = _table(*ARGS)
    assert "cannot be read" in caplog.text
    assert np.array_equal(again.sz, tb.sz) and np.array_equal(again.pm, tb.pm)
    with np.load(path) as z:  # replaced by a whole one
        assert np.array_equal(z["sz"], tb.sz)


def test_the_key_follows_the_arguments_and_the_computing_code(cache):
    a = tables.table_path("footprint", "x", (tyre_model,))
    assert a == tables.table_path("footprint", "x", (tyre_model,))
    assert a != tables.table_path("footprint", "y", (tyre_model,))
    assert a != tables.table_path("footprint", "x", (tyre_model, subsoil))
    assert a != tables.table_path("other", "x", (tyre_model,))
