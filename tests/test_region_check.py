"""The fast fidelity against the full one (the terrain engine driving the plan) on a small built-in season, and
the rut bound of a tracked machine against the package's soil law (docs/region.md, "Fast against full")."""

from __future__ import annotations

import numpy as np
import pytest

from symtrack.presets import soil_preset, vehicle_preset
from symtrack.region.check import fast_twin, soil_of
from symtrack.region.fast import run_season_fast
from symtrack.region.fleet import (
    COVER_FRACTIONS,
    PRESSURE_FRACTIONS,
    first_pass_rut_m,
    peak_pressure_factor,
    rut_table_m,
    track_machine,
)
from symtrack.soil import density


def test_the_first_pass_rut_is_the_soil_laws_load_and_rebound():
    soil = soil_preset("clayey_soil_thailand_38")
    m = track_machine("c", vehicle_preset("reference_crawler"), 8.0, 4.0)
    p = m.tracks.pressure_Pa
    k_eq = soil["k_c_N_per_m_n1"] / m.tracks.track_width_m + soil["k_phi_N_per_m_n2"]

    def by_hand(q):  # Bekker's static sinkage at q, then the rebound on the unloading line
        z_max = (q / k_eq) ** (1 / soil["bekker_n"])
        k_u = max(soil["elastic_stiffness_Pa_per_m"], soil["unloading_stiffness_floor"] * q / z_max)
        return z_max - q / k_u

    assert first_pass_rut_m(m, dict(soil)) == pytest.approx(by_hand(p), rel=1e-9)
    assert first_pass_rut_m(m, dict(soil)) > 0
    table = rut_table_m(m, dict(soil))
    full = PRESSURE_FRACTIONS.index(1.0)
    assert full == len(COVER_FRACTIONS) - 1 and len(table) == len(PRESSURE_FRACTIONS)
    assert table[0] == 0.0 and table[full] == first_pass_rut_m(m, dict(soil)) and np.all(np.diff(table) > 0)
    assert table[PRESSURE_FRACTIONS.index(0.5)] == pytest.approx(by_hand(0.5 * p), rel=1e-9)
    # beyond the static pressure (an accelerating track's pitched line): the same law at the larger pressure
    assert table[-1] == pytest.approx(by_hand(PRESSURE_FRACTIONS[-1] * p), rel=1e-9)


def test_the_tracked_columns_compression_is_bounded_by_the_rut():
    from symtrack.studies.operations import load_operation_spec

    spec = load_operation_spec("operation_small")
    ops, soil, depths = fast_twin(spec)
    fs = spec.base
    shape = (int(round(fs.size_m[0] / fs.cell_m)), int(round(fs.size_m[1] / fs.cell_m)))
    capped = run_season_fast(ops, shape, fs.cell_m, depths)
    import dataclasses

    free = run_season_fast([dataclasses.replace(o, rut_table_m=None) for o in ops], shape, fs.cell_m, depths)
    a = density.soil_arrays([soil], list(depths))
    v0 = np.broadcast_to(a["v0"][0], capped.state.shape)
    comp = density.column_compression_m(np.where(capped.state > 0, capped.state, v0), v0, depths)
    n = capped.counts.ravel().astype(float)
    # at most the rut of the track's largest pressure (its pitched line's peak where the plan's speed changes; a
    # cell partly under the track carries part of its pressure: less)
    from symtrack.studies.operations import PLAN_ACCEL_M_S2

    peak = peak_pressure_factor(ops[0].machine, PLAN_ACCEL_M_S2)
    assert 1.0 < peak < 1.1
    r_peak = np.interp(peak, PRESSURE_FRACTIONS, ops[0].rut_table_m)
    bound = r_peak * np.where(n > 0, n, 1.0) ** ops[0].rut_exponent
    # (the state is float32: v to 1e-7 of itself, the column of 0.8 m to 1e-7 m)
    assert np.all(comp <= bound + 1e-7)
    comp_free = density.column_compression_m(np.where(free.state > 0, free.state, v0), v0, depths)
    assert comp_free.max() > 2 * comp.max()  # the bound binds on this soil (its rut is under a millimetre)


def test_a_region_bounds_a_tracked_machines_compression_by_its_rut(tmp_path):
    """The region study's fast fidelity (what `symtrack region` runs) bounds a tracked machine's column compression
    by its rut on the day's soil, as the fast twin above and the terrain engine do (docs/region.md, step 4)."""
    import dataclasses
    import json

    from symtrack.region import demo, study
    from symtrack.region.inputs import load_region

    (tmp_path / "fleet.toml").write_text(
        "[machines.crawler]\nworking_width_m = 6.0\nturn_radius_m = 4.0\nsource = \"ASSUMED: a test crawler\"\n"
        "tracks = { contact_length_m = 2.4, track_width_m = 0.45, track_gauge_m = 1.5, mass_kg = 9000.0 }\n")
    systems = {"one": [{"name": "drilling", "machine": "crawler", "window": [262, 292], "tracks": "ab"}]}
    p = demo.write_region(tmp_path, n_fields=1, seed=3, systems=systems, years={2021: 0.0}, cell_m=0.2,
                          length_m=(60.0, 60.0), width_m=(36.0, 36.0))
    # the silt loam on a stiffer base law, whose rut (2.6 mm under 9 t) is less than the column would compress
    p.write_text(p.read_text().replace('fleet = "builtin"', 'fleet = "fleet.toml"')
                 .replace('"sandy_loam_15"', '"clayey_soil_thailand_38"'))
    fields = json.loads((tmp_path / "fields.geojson").read_text())
    fields["features"][0]["properties"]["soil"] = "silt_loam"
    (tmp_path / "fields.geojson").write_text(json.dumps(fields))
    spec = load_region(p)
    ctx = study.build_context(spec)
    f = spec.fields[0]
    ops = study.field_season_ops(ctx, f, 2021)
    op = ops[0]
    assert op.rut_table_m == rut_table_m(op.machine, op.soil_day)
    assert op.rut_exponent == op.soil_day["repeated_loading_exponent"] > 0
    shape = study._shape(spec, f)
    capped = run_season_fast(ops, shape, spec.cell_m, spec.depths_m)
    free = run_season_fast([dataclasses.replace(o, rut_table_m=None) for o in ops], shape, spec.cell_m,
                           spec.depths_m)
    v0 = np.broadcast_to(density.soil_arrays([op.soil_day], list(spec.depths_m))["v0"][0], capped.state.shape)
    comp = density.column_compression_m(np.where(capped.state > 0, capped.state, v0), v0, spec.depths_m)
    comp_free = density.column_compression_m(np.where(free.state > 0, free.state, v0), v0, spec.depths_m)
    n = capped.counts.ravel().astype(float)
    # a catalog's crawler has no centre of gravity's height: its static pressure everywhere (no pitched line)
    bound = op.rut_table_m[PRESSURE_FRACTIONS.index(1.0)] * np.where(n > 0, n, 1.0) ** op.rut_exponent
    assert np.all(comp <= bound + 1e-7)
    assert np.count_nonzero(comp_free > bound + 1e-7) > 1000  # the bound binds on this soil


@pytest.mark.slow
def test_fast_agrees_with_full_on_operation_small():
    """The full fidelity (the terrain engine, about 12 s once compiled) against its fast twin on the same cells:
    the trafficked share within 5 percentage points, the stress at depth within 5 %, the density change at
    0.1-0.5 m within 10 % (measured 6 / 4 / 4 % low at 0.1 / 0.3 / 0.5 m under the path-following law that drives
    it here, 11-15 % before the fast fidelity turned the tracks' rigid contacts in the turns and pitched their
    pressure line where the plan's speed changes: docs/region.md), the first-pass rut within 5 % of the
    engine's on the cells passed once."""
    from symtrack.region.check import compare, run_fast_twin
    from symtrack.studies.operations import load_operation_spec, run_season

    # the path-following law drives (operation.follower): the comparison is of the fidelities on the cells
    # the machine ran over, whoever drove it, and the MPC follower costs the season most of its CPU
    spec = load_operation_spec("operation_small", ['operation.follower="law"'])
    full = run_season(spec, None, figures=False)
    s = full.summary
    assert s["complete"], s["error"]
    # the run of tests/test_operations.py::test_operation_small_meets_the_tracking_target on the clay (the
    # built-in's soil; the same run to the last bit): the target, RMS lateral error <= 5 cm on the lines,
    # with one vehicle step per macro step (measured 0.035 m, max 0.12 m)
    assert s["turns_driven"] == spec.operations[0][1].turns == 2 and s["turns_lifted"] == 0
    assert s["rms_lateral_error_lines_m"] <= 0.05
    assert s["max_lateral_error_lines_m"] < 0.2
    fast = run_fast_twin(spec, rule="overlap")
    c = compare(full.terrain, full.summary, fast, fast[1], fast[2], 0.288)
    assert abs(c["trafficked_difference_points"]) < 5.0, c
    for d in ("0.1", "0.3", "0.5"):
        assert abs(c[f"stress_ratio_{d}m"] - 1) < 0.05, (d, c)
        assert abs(c[f"density_change_ratio_{d}m"] - 1) < 0.1, (d, c)
    t = full.terrain
    once = (t.sigma_max[:, 0] > 0) & (t.cycles == 1)
    ops, soil, _ = fast_twin(spec)
    r1 = ops[0].rut_table_m[PRESSURE_FRACTIONS.index(1.0)]
    assert float(np.median(t.z[once])) == pytest.approx(r1, rel=0.05)
    assert soil == soil_of(spec.operations[0][2].params)


def test_one_against_two_workers_alternates_the_pairs_and_takes_their_median(monkeypatch, tmp_path):
    """``symtrack bench region --workers``: each pair's ratio is its own 1-worker task time over its 2-worker one
    (pairs alternated, so a machine's drift moves both alike), the median over the pairs; ``--workers`` belongs
    to ``bench region`` only."""
    import argparse

    from symtrack.bench import homogeneous
    from symtrack.foundations.errors import ScenarioError
    from symtrack.region import check, study

    calls = []
    times = iter([40.0, 20.0, 30.0, 20.0, 36.0, 18.0])  # pairs: 2.0, 1.5, 2.0

    def fake_run_region(spec, out, workers, progress, outputs):
        calls.append(workers)
        t = next(times)
        rows = [{"cpu_time_s": 0.9 * t * workers}]
        return study.RegionResult(out, rows, 1, 0, t + 1.0, {}, {"plans_s": 0.5, "tasks_s": t})

    monkeypatch.setattr(study, "run_region", fake_run_region)
    rep = check.bench_rows(workers_only=True, repeats=3)
    assert calls == [1, 2, 1, 2, 1, 2]
    assert [r["speedup_vs_1_worker"] for r in rep["workers"] if r["workers"] == 2] == [2.0, 1.5, 2.0]
    assert rep["speedup_median"] == 2.0 and [r["repeat"] for r in rep["workers"]] == [0, 0, 1, 1, 2, 2]
    assert "median of 3 alternated pairs: 2.00 x" in check.bench_table(rep)
    ap = argparse.ArgumentParser()
    homogeneous.add_arguments(ap)
    with pytest.raises(ScenarioError, match="--workers is an option of `symtrack bench region`"):
        homogeneous.run_cli(ap.parse_args(["--workers", "--out", str(tmp_path / "b.json")]))
