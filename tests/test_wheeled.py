"""A wheeled machine's pass over a field (symtrack/vehicles/wheeled.py): the footprint's stress
moved along a path into the terrain's record (against the footprint evaluated directly at a
cell's centre), the same pass turned by 90 degrees giving the transposed field, cells out of
reach untouched bit for bit, the compression state by the virgin line's closed form, refusals;
and the example comparing a dry and a wet day, a crawler and a tractor."""

import math
import runpy
import sys

import numpy as np
import pytest

from symtrack.foundations.errors import ParameterError
from symtrack.model.parameters import SOIL_PARAMS
from symtrack.soil import density, moisture
from symtrack.terrain.storage import Grid, Terrain
from symtrack.vehicles import tyre, wheeled

DEPTHS = (0.1, 0.3, 0.5, 0.8)


def _terrain():
    soil = {s.name: s.default for s in SOIL_PARAMS if s.default is not None}
    soil["bulk_density_initial_Mg_per_m3"] = 1.2
    soil["yield_line_offset_ln_p"] = 0.0  # the virgin line alone: its closed form, nothing added by a second pass
    soil = moisture.apply_moisture(soil, {"water_content_kg_per_kg": 0.2, "compression_ptf": "defossez_2003_loess"})
    return Terrain(Grid((-2.0, -2.0), 0.1, (40, 40)), soil, DEPTHS)


def _wheel():
    ty = tyre.Tyre(0.48, 1.76, 31.9, 160.0)
    return wheeled.Wheel(tyre.contact(ty, 16.0, tyre.recommended_inflation_kPa(ty, 16.0), 0.025), 0.0, 0.0)


def test_pass_against_the_footprint_and_turned():
    w = _wheel()
    xs = np.arange(0.0, 1.0 + 1e-9, 0.025)
    t1 = _terrain()
    f1 = wheeled.wheeled_pass(t1, [w], np.column_stack([xs - 0.5, 0 * xs, 0 * xs]), 5.0)
    # the cell with centre (0.05, 0.05): the largest over the poses of the footprint at that point
    k = 20 * 40 + 20
    direct = np.max([tyre.footprint_stress_at_depth(w.contact.x_m + x, w.contact.y_m, w.contact.force_kN,
                                                    0.05, 0.05, DEPTHS, 5.0)[0][0] for x in xs - 0.5], axis=0)
    assert t1.sigma_max[k] == pytest.approx(1e3 * direct, rel=1e-6)
    assert f1["subsoil_sigma_z_max_kPa"][0] > 50.0
    # the same pass along y (psi = 90 deg): the transposed field (the footprint is symmetric in x, y)
    t2 = _terrain()
    wheeled.wheeled_pass(t2, [w], np.column_stack([0 * xs, xs - 0.5, 0 * xs + math.pi / 2]), 5.0)
    s1 = t1.sigma_max.reshape(40, 40, 4)
    s2 = t2.sigma_max.reshape(40, 40, 4).transpose(1, 0, 2)
    assert np.allclose(s1, s2, rtol=1e-5, atol=1e-3 * s1.max())
    # out of reach (1.5 m from every wheel position) untouched, bit for bit
    X, Y = np.meshgrid(np.arange(40) * 0.1 - 1.95, np.arange(40) * 0.1 - 1.95, indexing="ij")
    far = (np.hypot(np.maximum(np.abs(X.ravel()) - 0.5, 0), Y.ravel()) > wheeled.DEFAULT_REACH_M + 0.01)
    assert far.any() and not t1.sigma_max[far].any() and not t1.specific_volume[far].any()
    # the compression state: the virgin line's closed form at the stored mean normal stress where it yielded
    soils = wheeled.terrain_soils(t1)
    a = density.soil_arrays(soils)
    v = t1.specific_volume[k].astype(float)
    assert np.all((v == 0) | (v < a["v0"][0]))
    assert f1["bulk_density_max_Mg_per_m3"][0] > 1.2
    # a second identical pass changes nothing
    before = t1.specific_volume.copy()
    wheeled.wheeled_pass(t1, [w], np.column_stack([xs - 0.5, 0 * xs, 0 * xs]), 5.0)
    assert np.array_equal(before, t1.specific_volume)


def test_refusals():
    t = _terrain()
    with pytest.raises(ParameterError, match="apart, more than a quarter"):
        wheeled.wheeled_pass(t, [_wheel()], [[0, 0, 0], [0.1, 0, 0]], 5.0)
    with pytest.raises(ParameterError, match="wheels is empty"):
        wheeled.wheeled_pass(t, [], [[0, 0, 0]], 5.0)
    with pytest.raises(ParameterError, match="xi = 2.0"):
        wheeled.wheeled_pass(t, [_wheel()], [[0, 0, 0]], 2.0)


def test_example_day_and_machine(monkeypatch, capsys):
    import json
    monkeypatch.setattr(sys, "argv", ["compaction_day_and_machine.py", "--length", "1.0", "--passes", "1"])
    with pytest.raises(SystemExit) as e:
        runpy.run_path("examples/compaction_day_and_machine.py", run_name="__main__")
    assert e.value.code == 0
    out = json.loads(capsys.readouterr().out)
    dry, wet = (np.array(out["days"][d]["bulk_density_max_Mg_per_m3_by_pass"][-1]) for d in ("dry", "wet"))
    assert np.all(wet >= dry) and wet[0] > dry[0]
    tractor, crawler = (np.array(out[m]["subsoil_sigma_z_max_kPa"]) for m in ("tractor", "crawler"))
    assert np.all(tractor > crawler)
