"""The whole-field traffic study (symtrack/studies/field.py, docs/studies.md): the passes-per-cell
counts and the trafficked area against an independent count from the pass geometry, random
against controlled traffic, the refusal of bad spec values (the key named, nothing run), the
output files' schema, and the study as a sweep kind. A small field of 0.15 m cells (the 100 m x
100 m figures are the bench's and the note's, not a test's)."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from symtrack.cli.main import main as cli_main
from symtrack.foundations.errors import ScenarioError
from symtrack.simulation.plants import make_plant
from symtrack.soil import subsoil
from symtrack.studies import plan
from symtrack.studies.field import (
    PATTERNS,
    clear_previous_study,
    field_figures,
    lane_positions,
    load_field_spec,
    plan_passes,
    run_field_study,
    usable_band_m,
)
from symtrack.studies.field_plots import block_max
from symtrack.studies.runs import run_one
from symtrack.terrain.storage import Terrain
from symtrack.terrain.world import padding_m

CELL = 0.15
SMALL = ["field.size_m=[14.4, 8.1]", f"field.cell_m={CELL}", "field.passes=4", "field.headland_m=3.0",
         "field.lanes=2", "field.lane_spacing_m=3.0", "field.seed=3", "terrain.max_speed_m_s=3.0"]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("field") / "both"
    spec = load_field_spec("field_traffic", SMALL)
    return spec, run_field_study(spec, out=out), out


@pytest.fixture
def data_only(monkeypatch):
    """The study's folder without its drawings: each pattern's data files only (field.npz, passes.csv, the
    counts; ``_pattern_files(figures=False)``, the checkpoint's) and a stand-in for comparison.png. For the
    tests of resuming, interrupting and counting, which read the data files: the maps and the comparison were
    most of their CPU (12 of 16 s); they are drawn and checked in test_output_files_and_their_schema."""
    from symtrack.studies import field as field_module
    from symtrack.studies import field_plots

    pattern_files = field_module._pattern_files
    monkeypatch.setattr(field_module, "_pattern_files", lambda spec, pr, figures=True: pattern_files(spec, pr, False))
    monkeypatch.setattr(field_plots, "comparison_png", lambda figures: b"not drawn")


def _expected_counts(spec, lines, tol_lat, tol_long):
    """Per cell: the passes that surely load it and the passes that may (the cells within tol of a
    swept contact's edge are the undecided ones), from the pass geometry alone: each track's
    contact rectangle (l x b at y +- B/2 from the CG line, its centre e behind the CG) swept from
    the set-down at x_start to x_start +- pass_length; a cell counts when its square overlaps it."""
    fs, p = spec.field, spec.params
    nx, ny = (int(round(s / fs.cell_m)) for s in fs.size_m)
    xc = (np.arange(nx) + 0.5) * fs.cell_m
    yc = (np.arange(ny) + 0.5) * fs.cell_m
    X, Y = np.meshgrid(xc, yc, indexing="ij")
    sure = np.zeros((nx, ny), dtype=int)
    maybe = np.zeros((nx, ny), dtype=int)
    half_l = 0.5 * p["contact_length_m"] + 0.5 * fs.cell_m
    half_b = 0.5 * p["track_width_m"] + 0.5 * fs.cell_m
    for ln in lines:
        d = ln.direction
        c0 = ln.x_start_m - d * p["cg_ahead_of_contact_centre_m"]
        c1 = c0 + d * fs.length_m
        lo, hi = min(c0, c1) - half_l, max(c0, c1) + half_l
        for side in (1.0, -1.0):
            dy = np.abs(Y - (ln.y_m + side * 0.5 * p["track_gauge_m"]))
            sure += (dy < half_b - tol_lat) & (X > lo + tol_long) & (X < hi - tol_long)
            maybe += (dy < half_b + tol_lat) & (X > lo - tol_long) & (X < hi + tol_long)
    return sure, maybe


def test_controlled_traffic_counts_against_the_geometry(study):
    spec, res, _ = study
    pr = res.patterns["controlled"]
    shape = pr.terrain.grid.shape
    counts = pr.counts.reshape(shape)
    lines = plan_passes(spec, "controlled")
    k = lane_positions(spec.field, spec.params).size
    assert k == 2 and [ln.lane for ln in lines] == [0, 1, 0, 1]
    sure, maybe = _expected_counts(spec, lines, tol_lat=0.3 * CELL, tol_long=0.3 * CELL + 0.05)
    decided = sure == maybe
    assert decided.mean() > 0.9
    # every decided cell of a lane got passes / k passes, every decided cell off the lanes none
    assert np.array_equal(counts[decided], sure[decided])
    on_lane = decided & (sure > 0)
    assert on_lane.sum() > 500
    assert set(np.unique(counts[on_lane])) == {spec.field.passes // k}
    # the trafficked area lies between the sure cells and the cells that may be loaded
    f = pr.figures
    assert (maybe > 0).sum() >= f["trafficked_cells"] >= (sure > 0).sum()
    assert f["trafficked_area_fraction"] == pytest.approx(f["trafficked_cells"] / counts.size)
    assert f["passes_per_cell_histogram"][spec.field.passes // k] == int((counts == spec.field.passes // k).sum())


def test_random_traffic_counts_against_the_geometry(study):
    spec, res, _ = study
    pr = res.patterns["random"]
    counts = pr.counts.reshape(pr.terrain.grid.shape)
    lines = plan_passes(spec, "random")
    ys = np.array([ln.y_m for ln in lines])
    lo, hi = usable_band_m(spec.field, spec.params)
    half = 0.5 * (spec.params["track_gauge_m"] + spec.params["track_width_m"]) + padding_m(CELL)
    assert half < lo and hi < spec.field.size_m[1] - half
    assert ys.min() >= lo and ys.max() <= hi
    assert len({round(ln.y_m, 9) for ln in lines}) == len(lines)  # drawn, not repeated
    sure, maybe = _expected_counts(spec, lines, tol_lat=0.3 * CELL, tol_long=0.3 * CELL + 0.05)
    decided = sure == maybe
    assert np.array_equal(counts[decided], sure[decided])
    # the same seed draws the same positions; another seed others
    again = load_field_spec("field_traffic", SMALL)
    assert [ln.y_m for ln in plan_passes(again, "random")] == [ln.y_m for ln in lines]
    other = load_field_spec("field_traffic", [*SMALL, "field.seed=4"])
    assert [ln.y_m for ln in plan_passes(other, "random")] != [ln.y_m for ln in lines]


def test_controlled_traffic_tramples_less_area_for_the_same_passes(study):
    _, res, _ = study
    r, c = res.patterns["random"].figures, res.patterns["controlled"].figures
    assert r["passes_done"] == c["passes_done"] == 4
    assert c["trafficked_area_fraction"] < r["trafficked_area_fraction"]
    # the same work: each pattern loaded about the same cell-passes (the same contact swept)
    cell_passes = [sum(k * n for k, n in enumerate(f["passes_per_cell_histogram"])) for f in (r, c)]
    assert cell_passes[0] == pytest.approx(cell_passes[1], rel=0.03)
    assert c["passes_per_cell_max"] == 2 and c["passes_per_cell_mean_trafficked"] > r["passes_per_cell_mean_trafficked"]
    # the governor held the pass speed
    for pr in res.patterns.values():
        for rec in pr.records:
            assert rec["stopped_by"] == "distance"
            assert rec["distance_m"] == pytest.approx(8.4, abs=1e-6)
            assert rec["speed_end_m_s"] == pytest.approx(2.5, abs=0.25)


def test_output_files_and_their_schema(study):
    spec, res, out = study
    s = json.loads((out / "summary.json").read_text())
    assert s == json.loads(json.dumps(res.summary))
    assert s["schema_version"] == 1 and s["kind"] == "symtrack-field-study" and s["complete"] is True
    assert s["patterns_run"] == list(PATTERNS) and s["passes_per_pattern"] == 4
    assert s["field_cells"] == 96 * 54 and s["field_cell_m"] == CELL
    for key in ("build_s", "wall_time_s", "passes_wall_time_s", "sim_time_s", "load_average_1min", "path_note",
                "passes_count_source"):
        assert key in s
    assert (out / "comparison.png").stat().st_size > 1000
    assert "[field]" in (out / "field.resolved.toml").read_text()
    page = (out / "report.html").read_text()  # what ran, the patterns side by side, every map embedded
    assert "symtrack field:" in page and "<h2>Patterns</h2>" in page and "trafficked_area_fraction" in page
    # the figures by depth get a row per depth; a list of another kind does not, even of the same length (4 passes,
    # 4 depths: the passes' lateral positions were shown "at 0.1 m")
    assert "subsoil_sigma_z_max_kPa at 0.1 m" in page and "lateral_positions_m at" not in page
    assert page.count("data:image/png") >= 1 + 2 * len(PATTERNS)
    for name in PATTERNS:
        f = s["patterns"][name]
        hist = f["passes_per_cell_histogram"]
        assert sum(hist) == s["field_cells"]
        assert f["trafficked_cells"] == s["field_cells"] - hist[0]
        assert s[f"{name}_trafficked_area_fraction"] == f["trafficked_area_fraction"]
        for d, v in zip(f["subsoil_depths_m"], f["subsoil_sigma_z_max_kPa"], strict=True):
            assert s[f"{name}_subsoil_sigma_z_max_at_{d:g}m_kPa"] == v > 0
        for k in ("rut_mean_depth_mm", "rut_max_depth_mm", "sinkage_volume_m3", "load_cycles_histogram",
                  "subsoil_depths_m", "subsoil_sigma_z_max_kPa", "wall_time_s", "sim_time_s", "passes"):
            assert k in f
        assert 0 < f["rut_mean_depth_mm"] <= f["rut_max_depth_mm"]
        for d in range(len(f["subsoil_depths_m"])):
            assert sum(f[f"risk_fraction_of_trafficked_{c}"][d] for c in subsoil.RISK_NAMES) == pytest.approx(1.0)
            assert f"{name}_risk_fraction_of_field_high_at_{f['subsoil_depths_m'][d]:g}m" in s
        for png in ("sinkage_map.png", "passes_map.png", "risk_map.png", "density_map.png"):
            assert (out / name / png).stat().st_size > 1000
        # the bulk density by depth pass by pass (docs/subsoil.md "Bulk density"): from the initial, monotone
        table = np.array([f["bulk_density_initial_Mg_per_m3"]] + [r["bulk_density_max_Mg_per_m3"] for r in f["passes"]])
        assert table.shape == (5, len(f["subsoil_depths_m"])) and np.all(np.diff(table, axis=0) >= 0)
        assert table[-1, 0] > table[0, 0]
        rows = list(csv.DictReader((out / name / "passes.csv").open()))
        assert [int(r["pass"]) for r in rows] == [1, 2, 3, 4]
        assert [int(r["direction"]) for r in rows] == [1, -1, 1, -1]
        # the terrain file is the field after the passes: its record gives the summary's figures again
        t = Terrain.load(out / name / "field.npz")
        pr = res.patterns[name]
        with np.load(out / name / "passes_per_cell.npz") as z:
            assert str(z["kind"]) == "symtrack-field-passes" and int(z["schema_version"]) == 1
            assert tuple(z["shape"]) == t.grid.shape and float(z["cell_m"]) == CELL
            assert np.array_equal(z["passes"].ravel(), pr.counts)
        assert np.array_equal(t.z, pr.terrain.z) and np.array_equal(t.cycles, pr.terrain.cycles)
        again = field_figures(t, pr.counts, spec.params["precompression_stress_Pa"])
        for k, v in again.items():
            assert f[k] == pytest.approx(v), k


@pytest.mark.parametrize("override, key", [
    ("field.pattern=zigzag", "field.pattern"),
    ("field.passes=0", "field.passes"),
    ("field.headland_m=0.5", "field.headland_m"),
    ("field.lane_spacing_m=1.0", "field.lane_spacing_m"),
    ("field.lanes=9", "field.lanes"),
    ("field.pass_length_m=50.0", "field.pass_length_m"),
    ("field.speed_m_s=-1.0", "field.speed_m_s"),
    ("field.speed_m_s=5.0", "field.speed_m_s"),
    ("field.cell_m=0.5", "field.cell_m"),
    ("field.size_m=[14.4, 2.0]", "field.size_m"),
    ("field.colour=1", "colour"),
    ("terrain.size_m=[5.0, 5.0]", "terrain.size_m"),
    ("run.stop_after_distance_m=3.0", "stop_after_distance_m"),
    ("run.integrator=cvodes", "run.integrator"),
    ("vehicle.mass_kg=-5.0", "vehicle.mass_kg"),
])
def test_bad_spec_values_are_refused_with_the_key_named(override, key, tmp_path):
    with pytest.raises(ScenarioError, match=key.replace(".", r"\.")):
        load_field_spec("field_traffic", [*SMALL, override])
    out = tmp_path / "out"
    assert cli_main(["field", "field_traffic", "--out", str(out), "--quiet", *sum(
        (["--set", o] for o in (*SMALL, override)), [])]) == 2
    assert not out.exists() or not any(out.iterdir())


def test_the_field_study_is_a_sweep_kind(data_only):
    p = plan("field_traffic", {"vehicle.mass_kg": [5500.0, 8000.0]}, overrides=SMALL)
    assert p.source.kind == "field" and len(p.runs) == 2
    with pytest.raises(ScenarioError, match=r"vehicle\.mass_kg"):
        plan("field_traffic", {"vehicle.mass_kg": [5500.0, -1.0]}, overrides=SMALL)
    r = p.runs[1]
    task = {"id": r["id"], "kind": "field", "text": p.source.text, "name": p.source.name,
            "overrides": {**r["overrides"], "field.pattern": "controlled", "field.passes": 2}}
    done = run_one(task)
    assert done["status"] == "ok", done["error"]
    s = json.loads(done["files"]["summary.json"])
    assert s["patterns_run"] == ["controlled"] and s["complete"]
    assert "controlled/field.npz" in done["files"] and s["controlled_rut_max_depth_mm"] > 0


def test_ctrl_c_keeps_the_passes_done(tmp_path, data_only):
    """Ctrl-C during the third pass (raised from the plant's set-down, as the loop's interrupt
    watch raises it): the two passes done are written, marked incomplete, and the interrupt goes on."""
    spec = load_field_spec("field_traffic", [*SMALL, "field.pattern=random", "field.passes=3"])
    plant = make_plant(spec.scenario)
    start, calls = plant.start, []

    def start_then_interrupt(*a, **k):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return start(*a, **k)

    plant.start = start_then_interrupt
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        run_field_study(spec, out=out, plant=plant)
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and s["interrupted"] is True
    f = s["patterns"]["random"]
    assert f["passes_done"] == 2 and len(f["passes"]) == 2 and f["complete"] is False
    assert len(list(csv.DictReader((out / "random" / "passes.csv").open()))) == 2
    t = Terrain.load(out / "random" / "field.npz")
    # the field holds the two passes: the cells they loaded moved (an edge cell's rebound may end
    # above its rest: z < 0), no other cell did; the plastic cycles are among the loaded cells
    trafficked = sum(f["passes_per_cell_histogram"][1:])
    assert trafficked > 500 and int((t.z != 0).sum()) == trafficked
    assert 0 < int((t.cycles > 0).sum()) <= trafficked


def test_an_unwritable_out_is_refused_before_any_work(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert cli_main(["field", "field_traffic", "--out", str(blocker / "sub"), "--quiet"]) == 2


def test_a_reused_out_loses_only_the_previous_studys_files(tmp_path):
    (tmp_path / "random").mkdir()
    for p in ("summary.json", "comparison.png", "random/field.npz", "random/passes_map.png", "mine.txt",
              "random/notes.txt"):
        (tmp_path / p).write_text(json.dumps({"kind": "symtrack-field-study"}) if p == "summary.json" else "x")
    removed = clear_previous_study(tmp_path)
    assert sorted(p.relative_to(tmp_path).as_posix() for p in removed) == [
        "comparison.png", "random/field.npz", "random/passes_map.png", "summary.json"]
    assert (tmp_path / "mine.txt").exists() and (tmp_path / "random" / "notes.txt").exists()
    (tmp_path / "summary.json").write_text(json.dumps({"schema_version": 1}))  # a simulation's folder
    (tmp_path / "comparison.png").write_text("x")
    assert clear_previous_study(tmp_path) == [] and (tmp_path / "comparison.png").exists()


def test_a_pass_that_fails_is_reported_and_what_was_done_is_written(tmp_path, capsys, data_only):
    out = tmp_path / "out"
    args = ["field", "field_traffic", "--out", str(out), "--quiet", "--pattern", "random"]
    for o in (*SMALL, "field.passes=2", "run.duration_s=1.0"):
        args += ["--set", o]
    assert cli_main(args) == 1
    assert "run.duration_s = 1 s ended the pass" in capsys.readouterr().err
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and "random pass 1: run.duration_s" in s["error"]
    f = s["patterns"]["random"]
    assert f["passes_done"] == 1 and f["passes"][0]["stopped_by"] == "duration" and f["trafficked_cells"] > 0
    assert (out / "random" / "field.npz").is_file() and not (out / "controlled").exists()


def test_the_maps_of_a_large_field_keep_a_narrow_rut():
    """A rut two cells wide on a field of 1000 x 1000 cells, drawn in blocks: every block it
    touches shows it (each block its largest value), nothing else does."""
    risk = np.zeros((1000, 1000, 2), dtype=np.int8)
    risk[:, 501:503, 0] = 2
    out, f = block_max(risk, 200)
    assert f == 5 and out.shape == (200, 200, 2)
    assert (out[:, 100, 0] == 2).all() and out[:, :100, 0].max() == 0 and out[:, 101:, 0].max() == 0
    assert out[..., 1].max() == 0
    odd, f = block_max(np.ones((7, 3), dtype=np.uint16), 2)
    assert f == 4 and odd.shape == (2, 1) and (odd == 1).all()


def _arrays(path):
    return Terrain.load(path).arrays()


def _killed_at_pass(spec, out, k, kill):
    """Run the study with ``plant.start`` of pass ``k`` (counted over the study) interrupted by
    ``kill()``; returns the number of passes started."""
    plant = make_plant(spec.scenario)
    start, calls = plant.start, []

    def start_then(*a, **kw):
        calls.append(1)
        if len(calls) == k:
            kill()
        return start(*a, **kw)

    plant.start = start_then
    return plant, calls


def test_a_rerun_resumes_an_interrupted_study_and_gives_the_uninterrupted_result(study, tmp_path, data_only):
    """Ctrl-C at the random pattern's third pass, then the same study again into the same folder: it
    runs passes 3 and 4 only (and the controlled pattern), and every file of the random pattern's
    field equals the uninterrupted study's bit for bit."""
    spec = load_field_spec("field_traffic", SMALL)
    out = tmp_path / "out"

    def interrupt():
        raise KeyboardInterrupt

    plant, calls = _killed_at_pass(spec, out, 3, interrupt)
    with pytest.raises(KeyboardInterrupt):
        run_field_study(spec, out=out, plant=plant)
    plant2, calls2 = _killed_at_pass(spec, out, 99, interrupt)
    res = run_field_study(spec, out=out, plant=plant2)
    assert res.complete and len(calls2) == 2 + 4  # random passes 3, 4; controlled 1-4
    ref = study[2]
    for pattern in PATTERNS:
        a, b = _arrays(out / pattern / "field.npz"), _arrays(ref / pattern / "field.npz")
        assert all(np.array_equal(a[k], b[k]) for k in b), pattern
        with np.load(out / pattern / "passes_per_cell.npz") as x, np.load(ref / pattern / "passes_per_cell.npz") as y:
            assert np.array_equal(x["passes"], y["passes"])
        rows = list(csv.DictReader((out / pattern / "passes.csv").open()))
        ref_rows = list(csv.DictReader((ref / pattern / "passes.csv").open()))
        assert [(r["pass"], r["distance_m"], r["cells_loaded"]) for r in rows] == \
            [(r["pass"], r["distance_m"], r["cells_loaded"]) for r in ref_rows]
    s, s_ref = (json.loads((d / "summary.json").read_text()) for d in (out, ref))
    for k in ("random_trafficked_area_fraction", "controlled_trafficked_area_fraction"):
        assert s[k] == s_ref[k]


def test_a_killed_study_resumes_from_its_last_checkpoint(tmp_path, monkeypatch, data_only):
    """SIGKILL in the random pattern's third pass (checkpoints after every pass): the folder holds
    the two passes' checkpoint and no summary; a rerun runs the last pass only, and the field equals
    an uninterrupted study's."""
    import multiprocessing
    import os
    import signal

    from symtrack.studies import field as field_module

    monkeypatch.setattr(field_module, "CHECKPOINT_EVERY_S", 0.0)
    spec = load_field_spec("field_traffic", [*SMALL, "field.pattern=random", "field.passes=3"])
    out = tmp_path / "out"

    def child():
        plant, _ = _killed_at_pass(spec, out, 3, lambda: os.kill(os.getpid(), signal.SIGKILL))
        run_field_study(spec, out=out, plant=plant)

    proc = multiprocessing.get_context("fork").Process(target=child)
    proc.start()
    proc.join(300)
    assert proc.exitcode == -signal.SIGKILL
    assert not (out / "summary.json").exists()
    assert len(list(csv.DictReader((out / "random" / "passes.csv").open()))) == 2
    plant, calls = _killed_at_pass(spec, out, 99, lambda: None)
    res = run_field_study(spec, out=out, plant=plant)
    assert res.complete and len(calls) == 1
    ref = run_field_study(spec, out=tmp_path / "ref")
    a, b = _arrays(out / "random" / "field.npz"), _arrays(tmp_path / "ref" / "random" / "field.npz")
    assert all(np.array_equal(a[k], b[k]) for k in b)
    assert res.summary["random_trafficked_area_fraction"] == ref.summary["random_trafficked_area_fraction"]


def test_ctrl_c_between_a_pass_and_its_record_exits_130_and_keeps_the_passes_done(tmp_path, monkeypatch, capsys,
                                                                                 data_only):
    """Ctrl-C in the moment after a pass, while its record is made (the field's bulk density taken):
    `symtrack field` exits 130 with one line, no traceback; the folder holds the whole passes before
    it (passes.csv, field.npz and the counts agree), and the same command again runs the rest only."""
    from symtrack.studies import field as field_module

    args = ["field", "field_traffic", "--out", str(tmp_path / "out"), "--quiet",
            *(a for s in [*SMALL, "field.pattern=random", "field.passes=3"] for a in ("--set", s))]
    plants = []

    def make_plant_interrupted(scenario):  # Ctrl-C at the third density: pattern start, pass 1, pass 2
        plant = make_plant(scenario)
        density, calls = plant.world.bulk_density_max, []

        def density_then_interrupt():
            calls.append(1)
            if len(calls) == 3 and len(plants) == 1:
                raise KeyboardInterrupt
            return density()

        plant.world.bulk_density_max = density_then_interrupt
        plants.append(calls)
        return plant

    monkeypatch.setattr(field_module, "make_plant", make_plant_interrupted)
    assert cli_main(args) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1 and "interrupted (Ctrl-C)" in err
    out = tmp_path / "out"
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] is False and s["interrupted"] is True and s["patterns"]["random"]["passes_done"] == 1
    rows = list(csv.DictReader((out / "random" / "passes.csv").open()))
    assert [r["pass"] for r in rows] == ["1"] and rows[0]["bulk_density_max_Mg_per_m3"]
    t = Terrain.load(out / "random" / "field.npz")
    assert t.history[-1]["passes"] == 1
    with np.load(out / "random" / "passes_per_cell.npz") as z:
        assert int(z["passes"].max()) == 1
    capsys.readouterr()
    assert cli_main(args) == 0  # resumed: passes 2 and 3
    s = json.loads((out / "summary.json").read_text())
    assert s["complete"] and s["patterns"]["random"]["passes_done"] == 3
    assert len(plants[1]) == 1 + 2  # the pattern's start, then passes 2 and 3
    assert Terrain.load(out / "random" / "field.npz").history[-1]["passes"] == 3


def test_defer_interrupts_raises_a_ctrl_c_after_the_block():
    import os
    import signal

    from symtrack.foundations.interrupt import defer_interrupts

    done = []
    with pytest.raises(KeyboardInterrupt), defer_interrupts():
        os.kill(os.getpid(), signal.SIGINT)
        done.append("the rest of the block")
    assert done == ["the rest of the block"]
    with defer_interrupts():  # none: nothing raised
        done.append(1)
