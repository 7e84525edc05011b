"""A mixed region study (docs/region.md, "A mixed run"): the full fidelity on chosen fields, the fast one
elsewhere. The full fidelity's wheeled pass against the fast fidelity on the same field-season (the same plans,
machines and soils: the package's two models of a tyre's stress), a tracked machine driven on the terrain engine,
the fidelity recorded in every output, the outputs' schema the same, the resume of a full field-season, and the
refusals before any work."""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from symtrack.foundations.errors import ScenarioError
from symtrack.region import demo, study
from symtrack.region.inputs import load_region
from symtrack.region.study import run_region

# one field-season: two machines (the drill's tractor, the combine), one season
ONE = {"one": [{"name": "drilling", "machine": "drill_6m", "window": [262, 292]},
               {"name": "harvest", "machine": "combine_7m5", "window": [196, 220]}]}


def _region(folder: Path, years=None, full=('F002',), systems=None, length_m=(90.0, 100.0),
            width_m=(50.0, 60.0)) -> Path:
    p = demo.write_region(folder, n_fields=2, seed=7, systems=systems or ONE, years=years or {2021: 0.0},
                          length_m=length_m, width_m=width_m, spacing_m=160.0)
    p.write_text(p.read_text() + "\n[full_fidelity]\nfields = [" + ", ".join(f'"{f}"' for f in full) + "]\n")
    return p


def _npz(data: bytes) -> dict:
    with np.load(io.BytesIO(data)) as z:
        return {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """F001's season in each fidelity, in this process (no cluster), and its next season in the full one."""
    p = _region(tmp_path_factory.mktemp("full") / "in", years={2021: 0.0, 2022: 0.3})
    spec = load_region(p)
    study.check_plans(spec)
    ctx = study.build_context(spec)
    f = spec.fields[0]
    out = {}
    for fid in ("fast", "full"):
        spec.fields[0] = dataclasses.replace(f, fidelity=fid)
        out[fid] = study.field_season(ctx, 0, 2021, None)
    out["full_2022"] = study.field_season(ctx, 0, 2022, out["full"])
    return out


def test_the_wheeled_pass_agrees_with_the_fast_fidelity_on_the_same_season(both):
    """The full fidelity's wheeled pass (Keller's contact at every pose, 2 cm tables, the stress beside the tyres
    too) against the fast fidelity's stress profiles (the largest stress of a straight drive, 3 cm, under the
    strips only) on the same plans, machines and day's soils."""
    a, b = both["full"]["summary"], both["fast"]["summary"]
    assert a["fidelity"] == "full" and b["fidelity"] == "fast"
    # the cells under the tyres' strips (the full's: the wheel centres' paths widened by the tyre, per segment)
    assert abs(a["trafficked_fraction"] - b["trafficked_fraction"]) < 0.05, (a["trafficked_fraction"],
                                                                              b["trafficked_fraction"])
    ma, mb = _npz(both["full"]["files"]["maps.npz"]), _npz(both["fast"]["files"]["maps.npz"])
    ca, cb = ma["counts"] > 0, mb["counts"] > 0
    assert (ca & cb).sum() > 0.95 * cb.sum()  # the fast's cells are the full's
    for k, d in enumerate((0.1, 0.3, 0.5, 0.8)):
        tag = f"{d:g}m"
        # the largest stress: the same tyres on the same soil (the profile is the maximum of a straight drive)
        assert a[f"stress_max_{tag}_kPa"] == pytest.approx(b[f"stress_max_{tag}_kPa"], rel=0.01), tag
        # the mean stress under the cells both trafficked: within 3 % (the tables' steps, the arcs)
        both_cells = ca & cb
        r = ma["sigma_max_kPa"][..., k][both_cells].mean() / mb["sigma_max_kPa"][..., k][both_cells].mean()
        assert abs(r - 1) < 0.03, (tag, r)
        # the density change over the field: the full one a little larger (the soil beside the tyres is stressed
        # too), within 10 %
        ra = a[f"density_change_mean_{tag}_Mg_per_m3"] / b[f"density_change_mean_{tag}_Mg_per_m3"]
        assert 0.97 < ra < 1.10, (tag, ra)
    # the same schema: the same arrays, types and shapes
    assert set(ma) == set(mb)
    for k in ma:
        assert ma[k].dtype == mb[k].dtype and ma[k].shape == mb[k].shape, k
    assert set(a) == set(b)


def test_a_full_season_starts_from_the_state_the_season_before_left(both):
    s1, s2 = both["full"]["summary"], both["full_2022"]["summary"]
    # below the tillage (none here) the compaction persists and grows: the second season's density change at
    # 0.5 m is the first's and more, everywhere
    d1 = _npz(both["full"]["files"]["maps.npz"])["density_change_Mg_per_m3"]
    d2 = _npz(both["full_2022"]["files"]["maps.npz"])["density_change_Mg_per_m3"]
    assert np.all(d2 >= d1 - 1e-7)
    assert s2["density_change_mean_0.5m_Mg_per_m3"] > s1["density_change_mean_0.5m_Mg_per_m3"] > 0


def test_a_tracked_machine_is_driven_on_the_terrain_engine(tmp_path):
    """A tracked machine of a catalog in the full fidelity: the reference crawler's drive of the plan on the
    terrain engine (the law follower), its figures in the summary, the outputs' schema the fast one's; the engine's
    cells must be narrower than the track (refused before any work otherwise)."""
    (tmp_path / "fleet.toml").write_text(
        "[machines.crawler]\nworking_width_m = 6.0\nturn_radius_m = 4.0\n"
        "source = \"ASSUMED: the package's reference crawler (symtrack presets reference_crawler)\"\n"
        "tracks = { contact_length_m = 2.4, track_width_m = 0.45, track_gauge_m = 1.5, mass_kg = 5500.0 }\n")
    systems = {"one": [{"name": "drilling", "machine": "crawler", "window": [262, 292], "tracks": "ab"}]}
    p = demo.write_region(tmp_path, n_fields=1, seed=3, systems=systems, years={2021: 0.0}, cell_m=0.2,
                          length_m=(60.0, 60.0), width_m=(36.0, 36.0))
    # the engine's rule of a trafficked cell in the fast fidelity too; the silt loam (on the demo's clay loam, whose
    # preset is north_gower_clayey_loam_46, the law follower snakes: docs/region.md, "A mixed run")
    p.write_text(p.read_text().replace('fleet = "builtin"', 'fleet = "fleet.toml"')
                 .replace("cell_m = 0.2", 'cell_m = 0.2\nrule = "overlap"') + '\n[full_fidelity]\nfields = ["F001"]\n')
    fields = json.loads((tmp_path / "fields.geojson").read_text())
    fields["features"][0]["properties"]["soil"] = "silt_loam"
    (tmp_path / "fields.geojson").write_text(json.dumps(fields))
    spec = load_region(p)
    study.check_plans(spec)
    study.check_full(spec)
    ctx = study.build_context(spec)
    full = study.field_season(ctx, 0, 2021, None)
    s = full["summary"]
    drive = s["operations"][0]["drives"][0]
    assert s["fidelity"] == "full" and drive["carrier"] == "tracks on the terrain engine" and drive["complete"]
    assert drive["rut_max_depth_mm"] > 0 and drive["follower"] == "law"
    spec.fields[0] = dataclasses.replace(spec.fields[0], fidelity="fast")
    fast = study.field_season(ctx, 0, 2021, None)
    ma, mb = _npz(full["files"]["maps.npz"]), _npz(fast["files"]["maps.npz"])
    assert set(ma) == set(mb) and all(ma[k].shape == mb[k].shape and ma[k].dtype == mb[k].dtype for k in ma)
    # the plan's tracks: the fast fidelity's cells are the engine's (the cells a contact overlapped), the engine's
    # a little more (the drive about its lines): the trafficked share within 5 points
    ca, cb = ma["counts"] > 0, mb["counts"] > 0
    assert (ca & cb).sum() > 0.95 * cb.sum()
    assert abs(s["trafficked_fraction"] - fast["summary"]["trafficked_fraction"]) < 0.05
    # the stress at depth under the cells both trafficked: the engine's moving, pitching tracks against the static
    # pressure line (a catalog's crawler has no centre of gravity's height: no pitched line where the plan's speed
    # changes), the turns of 4 m the turned contacts' in both: measured 1.05-1.06 times it at 0.1-0.8 m
    for k in range(4):
        r = ma["sigma_max_kPa"][..., k][ca & cb].mean() / mb["sigma_max_kPa"][..., k][ca & cb].mean()
        assert 0.95 < r < 1.3, (k, r)
    # cells as wide as the track: refused before any work, naming the field, the machine and the range
    p.write_text(p.read_text().replace("cell_m = 0.2", "cell_m = 0.5"))
    spec = load_region(p)
    study.check_plans(spec)
    with pytest.raises(ScenarioError, match=r"field 'F001', 2021, operation 'drilling' in the full fidelity: "
                                            r"cell_m = 0.5: .* machine 'crawler' .* the allowed range is "
                                            r"\(0, 0.45\) m"):
        study.check_full(spec)


def _hashes(out: Path) -> dict:
    return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted((out / "fields").rglob("maps.npz"))}


def test_a_mixed_run_records_the_fidelity_and_resumes_a_full_field_season(tmp_path):
    drill = {"one": ONE["one"][:1]}  # one machine: the worker builds its tables once
    # the records and the resume, not the physics: smaller fields than the comparison's (the full fidelity's wheeled
    # pass costs per pose of the plan: about a third of the fields' area, a third of the time)
    p = _region(tmp_path / "in", systems=drill, length_m=(60.0, 66.0), width_m=(44.0, 48.0))
    res = run_region(load_region(p), tmp_path / "out", workers=1, progress=False)
    out = tmp_path / "out"
    assert res.ran == 2
    assert {r["field_id"]: r["fidelity"] for r in res.rows} == {"F001": "fast", "F002": "full"}
    import csv

    with open(out / "fields.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [(r["field_id"], r["fidelity"]) for r in table] == [("F001", "fast"), ("F002", "full")]
    assert json.loads((out / "summary.json").read_text())["fields_full_fidelity"] == ["F002"]
    assert json.loads((out / "region.json").read_text())["fields_full_fidelity"] == ["F002"]
    html = (out / "report.html").read_text()
    assert "the full fidelity (each plan driven over the field&#x27;s terrain) on 1 field(s): F002" in html or \
        "the full fidelity (each plan driven over the field's terrain) on 1 field(s): F002" in html
    # a full field-season lost (as a kill before its commit leaves it): the rerun runs it alone, bit for bit
    ref = _hashes(out)
    shutil.rmtree(out / "fields" / "F002" / "2021")
    res = run_region(load_region(p), out, workers=1, progress=False)
    assert res.ran == 1 and res.skipped == 1
    assert _hashes(out) == ref


def test_the_full_fidelitys_fields_are_checked_and_drawn(tmp_path):
    p = _region(tmp_path, full=("F009",))
    with pytest.raises(ScenarioError, match=r"full_fidelity.fields\[0\] = 'F009' is not a field of fields_file "
                                            r"\(its fields: F001, F002\)"):
        load_region(p)
    text = p.read_text().replace('fields = ["F009"]', "share = 1.5")
    p.write_text(text)
    with pytest.raises(ScenarioError, match=r"full_fidelity.share = 1.5 is outside the allowed range \[0, 1\]"):
        load_region(p)
    p.write_text(text.replace("share = 1.5", 'vehicle = "tractor_x"'))
    with pytest.raises(ScenarioError, match=r"full_fidelity.vehicle = 'tractor_x'"):
        load_region(p)
    # a share of the fields drawn with the study's seed: the same fields each time, the named ones kept
    p.write_text(text.replace("share = 1.5", "share = 0.5"))
    drawn = [f.field_id for f in load_region(p).fields if f.fidelity == "full"]
    assert len(drawn) == 1 and drawn == [f.field_id for f in load_region(p).fields if f.fidelity == "full"]
    p.write_text(text.replace("share = 1.5", 'share = 1.0\nfields = ["F001"]'))
    assert [f.fidelity for f in load_region(p).fields] == ["full", "full"]
