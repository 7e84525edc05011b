"""What a new user met reading the docs (issue 41), each answered where it happens: the console line of a
field study's pattern, the starting files' headers, the scenario keys' table, the presets' sources and
their compact view, the field study's soil record, its per-depth strength and its density."""

from __future__ import annotations

import math

import pytest

from symtrack.cli.field import pattern_lines


def test_the_pattern_line_counts_cells_by_pass_count():
    f = {"passes_per_cell_histogram": [9048, 17, 7, 2592], "trafficked_area_fraction": 0.2243,
         "rut_mean_depth_mm": 0.7, "rut_max_depth_mm": 1.25, "passes_done": 6, "wall_time_s": 0.6,
         "subsoil_depths_m": [0.1, 0.3], "risk_fraction_of_field_medium": [0.061, 0.028]}
    lines = pattern_lines("controlled", f)
    assert "cells by pass count {0: 9048, 1: 17, 2: 7, 3: 2592}" in lines[0]
    assert "per pass count" not in lines[0]
    assert lines[1] == "  medium risk (% of the field): 0.1 m 6.10 %, 0.3 m 2.80 %"


def test_the_pattern_lines_give_the_stress_and_the_density_by_depth():
    """A field's console lines say the largest vertical stress and bulk density below the tracks by depth (a
    newcomer found the rut and the risk there, not the stress or the density)."""
    f = {"passes_per_cell_histogram": [10, 5], "trafficked_area_fraction": 0.3, "rut_mean_depth_mm": 1.2,
         "rut_max_depth_mm": 2.1, "passes_done": 4, "wall_time_s": 0.5, "subsoil_depths_m": [0.1, 0.3],
         "subsoil_sigma_z_max_kPa": [38.04, 31.2], "risk_fraction_of_field_medium": [0.6, 0.4],
         "passes": [{"bulk_density_max_Mg_per_m3": [1.2531, 1.2522]},
                    {"bulk_density_max_Mg_per_m3": [1.25398, 1.25327]}]}
    lines = pattern_lines("random", f)
    assert "  largest vertical stress (kPa): 0.1 m 38.0, 0.3 m 31.2" in lines
    assert "  largest bulk density after the passes (Mg/m^3): 0.1 m 1.2540, 0.3 m 1.2533" in lines


def test_a_value_given_equal_to_the_bases_derived_one_is_kept(tmp_path):
    """sandy_loam_15's topsoil is 1.55 Mg/m^3, so its derived subsoil density is 1.55 too: a file (or a
    scenario) that loosens the topsoil to 1.35 and gives the subsoil 1.55 keeps its subsoil at 1.55, not
    re-derived to the new topsoil's 1.35."""
    from symtrack.presets.catalog import read_preset_file
    from symtrack.simulation.scenario import load_scenario

    path = tmp_path / "two_layers.toml"
    path.write_text('base = "sandy_loam_15"\nsubsoil_top_m = 0.25\nbulk_density_initial_Mg_per_m3 = 1.35\n'
                    "subsoil_bulk_density_initial_Mg_per_m3 = 1.55\n")
    values, _, _ = read_preset_file(path, "soil")
    assert values["bulk_density_initial_Mg_per_m3"] == 1.35
    assert values["subsoil_bulk_density_initial_Mg_per_m3"] == 1.55
    sc = load_scenario("validation", ["soil.preset=sandy_loam_15", "soil.bulk_density_initial_Mg_per_m3=1.35",
                                      "soil.subsoil_bulk_density_initial_Mg_per_m3=1.55"])
    assert sc.soil["subsoil_bulk_density_initial_Mg_per_m3"] == 1.55
    # what is not given is still derived from the new values
    sc = load_scenario("validation", ["soil.preset=sandy_loam_15", "soil.bulk_density_initial_Mg_per_m3=1.35"])
    assert sc.soil["subsoil_bulk_density_initial_Mg_per_m3"] == 1.35


def _two_layer_soil(tmp_path):
    from symtrack.presets.catalog import read_preset_file

    path = tmp_path / "two_layers.toml"
    path.write_text('base = "clayey_soil_thailand_38"\nsubsoil_top_m = 0.25\nbulk_density_initial_Mg_per_m3 = 1.35\n'
                    "subsoil_bulk_density_initial_Mg_per_m3 = 1.55\n")
    return read_preset_file(path, "soil")[0]


def test_a_further_pass_never_loosens_a_depth(tmp_path):
    """The rut bounds the column's compression (density.cap_to_rut); a later pass that compresses the
    topsoil more than its rut deepens must not undo what an earlier pass compressed at 0.3 m (the field's
    bulk_density_max_Mg_per_m3 fell from one pass to the next, 1.5505 -> 1.5505): World.fold_pass on one
    cell, the first pass loading every depth, the next ones the topsoil alone, the rut growing little."""
    from types import SimpleNamespace

    import numpy as np

    from symtrack.soil import density
    from symtrack.terrain.world import World

    soil = _two_layer_soil(tmp_path)
    depths = [0.1, 0.3, 0.5, 0.8]
    storage = SimpleNamespace(sigma_max=np.zeros((1, 4), np.float32), specific_volume=np.zeros((1, 4), np.float32),
                              soil_index=np.zeros(1, np.int64), subsoil_depths_m=depths, z=np.zeros(1))
    world = SimpleNamespace(storage=storage, touched=np.ones(1, bool), soils=[soil], cell_day=None,
                            geostatic_Pa=lambda: density.geostatic_table([soil], depths),
                            layer_arrays=lambda: density.soil_arrays([soil], depths))
    v0 = density.soil_arrays([soil], depths)["v0"]
    previous = density.bulk_density(storage.specific_volume, storage.soil_index, [soil], depths)[0]
    for k in range(6):
        world.pass_sigma = np.array([[60e3, 40e3, 25e3, 15e3] if k == 0 else [60e3, 5e3, 3e3, 2e3]], np.float32)
        # the rut: below the first pass's column compression (the cap binds), then growing by little
        storage.z[0] = 0.01 if k == 0 else storage.z[0] + 2e-5
        World.fold_pass(world)
        rho = density.bulk_density(storage.specific_volume, storage.soil_index, [soil], depths)[0]
        assert np.all(rho >= previous - 1e-6), (k, previous, rho)  # (float32 state)
        v = np.where(storage.specific_volume > 0, storage.specific_volume, v0).astype(float)
        assert density.column_compression_m(v, v0, depths)[0] <= storage.z[0] * (1 + 1e-6)  # the rut's bound holds
        previous = rho
    assert rho[0] > 1.36  # the topsoil kept compacting


def test_the_rut_bound_of_a_first_pass_is_unchanged():
    """From the initial state (no earlier pass) the cap is the compression scaled to the rut, as before."""
    import numpy as np

    from symtrack.soil import density

    v0 = np.array([[2.0, 1.7]])
    state = np.array([[1.9, 1.65]], np.float32)
    assert density.cap_to_rut(state, np.array([0]), v0, [0.1, 0.3], np.array([0.002])) == 1
    v = state.astype(float)
    assert density.column_compression_m(v, v0, [0.1, 0.3])[0] == pytest.approx(0.002, rel=1e-5)
    assert (2.0 - v[0, 0]) / (2.0 - 1.9) == pytest.approx((1.7 - v[0, 1]) / (1.7 - 1.65), rel=1e-5)


def test_a_preset_files_sources_say_where_each_value_comes_from(tmp_path):
    from symtrack.presets.catalog import describe

    path = tmp_path / "two_layers.toml"
    path.write_text('base = "clayey_soil_thailand_38"\nsubsoil_top_m = 0.25\nbulk_density_initial_Mg_per_m3 = 1.35\n'
                    "subsoil_bulk_density_initial_Mg_per_m3 = 1.55\n[sources]\n"
                    'bulk_density_initial_Mg_per_m3 = "core samples, 2025"\n')
    rows = {r[0]: r[4] for r in describe("soil", str(path))}
    base = {r[0]: r[4] for r in describe("soil", "clayey_soil_thailand_38")}
    assert rows["bekker_n"] == f"from clayey_soil_thailand_38: {base['bekker_n']}" and base["bekker_n"]
    assert rows["subsoil_top_m"] == "set in two_layers.toml"
    assert rows["subsoil_bulk_density_initial_Mg_per_m3"] == "set in two_layers.toml"
    assert rows["bulk_density_initial_Mg_per_m3"] == "set in two_layers.toml: core samples, 2025"
    assert rows["compression_index_lambda"].startswith("derived from the initial specific volume")
    assert rows["particle_density_Mg_per_m3"] == \
        "from clayey_soil_thailand_38: default: the usual particle density of mineral soils"
    for name, src in {**rows, **base}.items():  # every value has a source, none a path into the code
        assert src and "n/a" not in src and "symtrack/" not in src and ".py" not in src, (name, src)


def test_every_registry_default_says_where_it_comes_from():
    from symtrack.model.parameters import SOIL_PARAMS, VEHICLE_PARAMS

    for s in SOIL_PARAMS + VEHICLE_PARAMS:
        assert (s.default is None) == (not s.default_source), s.name


def test_every_declared_parameter_has_a_source_and_its_names_unit():
    """Every parameter a vehicle, a soil law, the cell equation or the soil declares says where it comes
    from, none by a path into the code, and its unit is its name's (the one without a suffix declared)."""
    from symtrack.foundations.params import unit_of_name
    from symtrack.model.parameters import model_params, soil_params, spec
    from symtrack.soil import law as soil_law
    from symtrack.vehicles import registry

    specs = {s.name: s for s in soil_params()}
    for v in registry.REGISTRY.values():
        for law in soil_law.REGISTRY.values():
            specs.update((s.name, s) for s in model_params(vehicle=v, law=law))
    assert len(specs) == 47 and all(spec(n) is s for n, s in specs.items())
    for s in specs.values():
        assert s.source and "symtrack/" not in s.source and ".py" not in s.source, s.name
        assert s.unit == unit_of_name(s.name) or (unit_of_name(s.name) == "-" and s.unit != "-"), s.name
    assert specs["internal_resistance_per_km_h"].unit == "h/km" and specs["mass_kg"].unit == "kg"


def test_the_presets_default_view_fits_100_columns_with_each_source_once(tmp_path, capsys):
    from symtrack.cli.main import main

    assert main(["presets", "clayey_soil_thailand_38"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert max(len(line) for line in lines) <= 100
    friction = next(line for line in lines if line.startswith("friction_angle_rad"))
    assert "0.226893 (13 deg)" in friction
    note = next(line for line in lines if line.startswith("[1] "))
    assert out.count(note) == 1  # the long source once, by its number
    assert sum(line.endswith(" [1]") for line in lines) > 5
    assert main(["presets", "clayey_soil_thailand_38", "--wide"]) == 0
    wide = capsys.readouterr().out
    assert "| friction_angle_rad | 0.226893 (13 deg) | rad | Mohr-Coulomb internal friction angle phi |" in wide


# ---- the keys of a simulation: one table per section in docs/scenarios.md, made from the loader's checks ----

def test_the_docs_key_tables_are_the_loaders():
    """docs/scenarios.md holds what symtrack.simulation.keys makes (make keys writes it again)."""
    from pathlib import Path

    from symtrack.simulation import keys

    text = (Path(__file__).parent.parent / "docs" / "scenarios.md").read_text()
    block = text.split(keys.BEGIN, 1)[1].split(keys.END, 1)[0]
    assert block.strip() == keys.key_tables().strip(), "docs/scenarios.md's key tables are stale: run make keys"


def test_the_key_declarations_cover_every_key_the_loader_takes():
    import dataclasses

    from symtrack.model.options import MODEL_KEYS, scenario_keys
    from symtrack.simulation.scenario import RUN_KEYS, SIMULATION_RUN_KEYS, START_KEYS, TORQUE_KEYS, Start
    from symtrack.terrain.settings import TERRAIN_KEYS, TerrainSettings

    assert set(SIMULATION_RUN_KEYS) <= set(RUN_KEYS)
    assert list(MODEL_KEYS) == scenario_keys()
    assert list(START_KEYS) == [f.name for f in dataclasses.fields(Start)]
    assert list(TORQUE_KEYS) == ["t_s", "left_N_m", "right_N_m", "event"]
    assert list(TERRAIN_KEYS) == [f.name for f in dataclasses.fields(TerrainSettings) if f.name != "given"]


def _numeric(keys):
    return [k for k in keys.values() if k.low is not None and math.isfinite(k.high) and not k.allowed]


def test_the_declared_ranges_are_the_ones_the_loader_enforces():
    """Each declared bound of [run], [model], [start] and [terrain]: a value just beyond it is refused naming
    the key, a value at it (where closed) is taken."""
    from symtrack.foundations.errors import ScenarioError
    from symtrack.model.options import MODEL_KEYS
    from symtrack.simulation.scenario import RUN_KEYS, START_KEYS, load_scenario
    from symtrack.terrain.settings import TERRAIN_KEYS

    base = ["run.duration_s=1", "run.output_dt_s=0.001"]
    for section, keys in (("run", RUN_KEYS), ("model", MODEL_KEYS), ("start", START_KEYS),
                          ("terrain", TERRAIN_KEYS)):
        for k in _numeric(keys):
            if section == "run" and k.name in ("duration_s", "rms_exclude_first_m"):
                continue  # (the run's length bounds the output step; rms_exclude_first_m is an MPC run's)
            extra = ["run.integrator=grid_fast"] if section == "terrain" else []
            beyond = k.high + max(1.0, abs(k.high)) if k.integer else k.high * 1.5 + 1e-9
            with pytest.raises(ScenarioError, match=f"{section}.{k.name} = "):
                load_scenario("validation", [*base, *extra, f"{section}.{k.name}={beyond!r}"])
            below = k.low - 1 if k.integer else (k.low if k.low_open else k.low - 1e-3 - abs(k.low) * 0.5)
            with pytest.raises(ScenarioError, match=f"{section}.{k.name} = "):
                load_scenario("validation", [*base, *extra, f"{section}.{k.name}={below!r}"])


def test_a_starting_file_names_itself_and_points_at_the_docs_not_the_code(tmp_path, capsys):
    from pathlib import Path

    from symtrack.cli.main import main
    from symtrack.cli.run import NEW_KINDS

    docs = Path(__file__).parent.parent / "docs"
    for kind in NEW_KINDS:
        out = tmp_path / f"my_{kind}_run.toml"
        assert main(["new", kind, "--out", str(out)]) == 0
        text = out.read_text()
        assert f"symtrack run {out} --out out/my_{kind}_run" in text
        assert f"{kind}.toml" not in text and "symtrack/" not in text and ".py" not in text
        for page, heading in (("scenarios.md", "Keys of a simulation"), ("studies.md", "The spec"),
                              ("studies.md", "Field operations"), ("control.md", "")):
            if page in text and heading and f'"{heading}"' in text.replace("\n# ", " "):
                assert f"## {heading}" in (docs / page).read_text()
    assert '"Keys of a simulation"' in (tmp_path / "my_simulation_run.toml").read_text().replace("\n# ", " ")


# ---- a field study of a two-layer soil: its record of the soil, the strength by depth, the density's change ----

FIELD_TOML = """
name = "two_layers"
[run]
output_dt_s = 0.01
integrator = "grid_fast"
duration_s = 60.0
[vehicle]
preset = "reference_crawler"
[soil]
preset = "two_layers.toml"
[terrain]
max_speed_m_s = 3.0
[field]
size_m = [14.4, 8.1]
cell_m = 0.1
pattern = "controlled"
passes = 2
lane_spacing_m = 3.0
lanes = 2
headland_m = 3.0
speed_m_s = 2.5
torque_N_m = 2000.0
"""


@pytest.fixture(scope="module")
def two_layer_field(tmp_path_factory):
    from symtrack.cli.main import main

    folder = tmp_path_factory.mktemp("field")
    _two_layer_soil(folder)
    (folder / "f.toml").write_text(FIELD_TOML)
    assert main(["run", str(folder / "f.toml"), "--out", str(folder / "out"), "--quiet"]) == 0
    return folder / "out"


def test_the_field_records_the_resolved_soil_and_its_report_describes_it(two_layer_field):
    import tomllib

    resolved = tomllib.loads((two_layer_field / "field.resolved.toml").read_text())
    soil = resolved["soil"]
    assert soil["preset"].endswith("two_layers.toml")
    assert soil["bulk_density_initial_Mg_per_m3"] == 1.35 and soil["subsoil_bulk_density_initial_Mg_per_m3"] == 1.55
    assert soil["subsoil_top_m"] == 0.25 and soil["precompression_stress_Pa"] > 0 and soil["bekker_n"] == 0.5
    assert resolved["vehicle"]["mass_kg"] > 0
    report = (two_layer_field / "report.html").read_text()
    for text in ("topsoil: initial dry bulk density", "subsoil (from 0.25 m): initial dry bulk density",
                 "clay / silt / sand", "matric suction", "precompression stress at 0.3 m"):
        assert text in report, text


def test_the_field_summary_gives_the_strength_by_depth(two_layer_field):
    import json

    s = json.loads((two_layer_field / "summary.json").read_text())
    by_depth = s["patterns"]["controlled"]["subsoil_precompression_stress_by_depth_kPa"]
    assert "controlled_subsoil_precompression_stress_kPa" not in s  # (it was the weakest depth's, unnamed)
    assert s["controlled_subsoil_precompression_stress_min_kPa"] == min(by_depth)
    for d, v in zip(s["patterns"]["controlled"]["subsoil_depths_m"], by_depth, strict=True):
        assert s[f"controlled_subsoil_precompression_stress_at_{d:g}m_kPa"] == v
    report = (two_layer_field / "report.html").read_text()
    assert "subsoil_precompression_stress_by_depth_kPa at 0.3 m" in report
    assert "bulk_density_initial_Mg_per_m3 at 0.1 m" in report


def test_the_density_map_draws_the_change_from_the_initial_density(monkeypatch):
    import matplotlib.axes
    import numpy as np

    from symtrack.reports.subsoil_plots import density_map_png

    shown = []
    imshow = matplotlib.axes.Axes.imshow
    monkeypatch.setattr(matplotlib.axes.Axes, "imshow",
                        lambda self, data, **kw: shown.append((np.array(data), kw)) or imshow(self, data, **kw))
    rho0 = np.broadcast_to(np.array([1.35, 1.55]), (4, 3, 2)).copy()
    rho = rho0.copy()
    rho[1, 1, 0] = 1.37  # the topsoil's compaction: 0.02 on 1.35
    rho[1, 1, 1] = 1.555
    density_map_png(rho, [0.1, 0.3], (0, 4, 0, 3), initial_Mg_per_m3=rho0)
    (top, kw), (sub, _) = shown
    assert kw["vmin"] == 0.0 and kw["vmax"] == pytest.approx(0.02)
    assert top.max() == pytest.approx(0.02) and sub.max() == pytest.approx(0.005) and top.min() == 0.0


def test_getting_starteds_table_of_soils_is_the_presets():
    """docs/getting-started.md, step 4: the table of the built-in soils by texture, density and suction
    holds every soil preset, with the values `symtrack presets NAME` shows (to the table's digits)."""
    import re
    from pathlib import Path

    from symtrack.presets import soil_preset
    from symtrack.presets.catalog import preset_names

    text = (Path(__file__).parents[1] / "docs" / "getting-started.md").read_text()
    rows = [ln for ln in text.splitlines() if ln.startswith("| `")]
    named = set()
    for ln in rows:
        cells = [c.strip() for c in ln.strip("|").split("|")]
        names = re.findall(r"`([a-z0-9_]+)`", cells[0])
        dens = [float(v) for v in cells[3].split(",")]
        suct = [float(v) for v in cells[4].split(",")]
        frac = [float(v) for v in cells[2].split("/")]
        for k, name in enumerate(names):
            p = soil_preset(name)
            named.add(name)
            assert frac == pytest.approx([p["clay_kg_per_kg"], p["silt_kg_per_kg"], p["sand_kg_per_kg"]]), name
            assert dens[min(k, len(dens) - 1)] == pytest.approx(p["bulk_density_initial_Mg_per_m3"]), name
            assert suct[min(k, len(suct) - 1)] == pytest.approx(p["matric_suction_kPa"], rel=0.1, abs=0.006), name
    assert named == set(preset_names("soil"))
