import os

# The generated model code compiled at -O0 for the tests (symtrack/toolchain/cache.py, OPT_LEVEL_ENV): the
# same arithmetic as the tuned flags for a seventh of gcc's time on the large Jacobians; the tuned kernels
# (the terrain engine, the SIMD check) keep their flags. Set before anything is built; the processes the
# tests start (the CLI, Dask workers) inherit it. SYMTRACK_OPT_LEVEL= (empty) runs the tests on the tuned
# flags.
os.environ.setdefault("SYMTRACK_OPT_LEVEL", "0")
# the tuned kernels (the terrain engine) at -O1 with their other flags: a third of gcc's -O3 time, the same
# arithmetic and, on the tests' fields, the same speed (SYMTRACK_TUNED_OPT_LEVEL; the SIMD check clears it)
os.environ.setdefault("SYMTRACK_TUNED_OPT_LEVEL", "1")

import pytest

from symtrack.model import SystemModel
from symtrack.presets import soil_preset, vehicle_preset


@pytest.fixture(scope="session")
def model():
    return SystemModel()


@pytest.fixture(scope="session")
def params():
    return {**vehicle_preset("reference_crawler"), **soil_preset("clayey_soil_thailand_38")}


def run_once(scenario, model=None, **plant_kw):
    """One run of a scenario through the time loop with the plant it asks for (a built model
    may be reused)."""
    from symtrack.simulation import loop
    from symtrack.simulation.plants import make_plant

    return loop.run(scenario, make_plant(scenario, model=model, **plant_kw))


# ---- the parallel run (pytest-xdist, `-n 2 --dist loadfile` in pyproject.toml) --------------------------
# Each test file runs whole on one worker, in file order, as in a serial run (its module-scoped
# fixtures, the expensive worlds, runs and sweeps, are built once). The files start slowest first
# (longest processing time first: no long file is left to start last on one worker while the other
# is idle). SLOW_S are seconds measured in a serial run on 2 cores (setup + call, --durations): an
# ordering hint only; a test not listed counts as 1 s.
SLOW_S = {
    "tests/test_terrain_examples.py::test_bench_terrain_quick": 63,
    "tests/test_terrain_pool.py::test_pool_and_brute_force_give_the_same_vehicle_motion": 58,
    "tests/test_terrain_pool_passes.py::test_two_passes_equal_one_pass_save_load_and_a_second_pass": 53,
    "tests/test_compiled.py::test_compiled_functions_agree_with_interpreted": 29,
    "tests/test_control_rti.py::test_compiled_mpc_cached_across_processes[ipopt-1]": 28,
    "tests/test_sweep.py::test_a_failing_run_is_recorded_and_a_rerun_redoes_only_it": 26,
    "tests/test_terrain_engine.py::test_pool_equals_one_channel_per_cell_and_brute_force": 23,
    "tests/test_terrain_cli.py::test_simulate_with_terrain_out_and_in": 23,
    "tests/test_control_examples.py::test_jit_build_runs": 22,
    "tests/test_terrain_compiled.py::test_grid_rosenbrock_matches_idas": 19,
    "tests/test_terrain_engine.py::test_engine_matches_idas_on_a_small_field": 18,
    "tests/test_control_grid.py::test_grid_plant_with_the_compiled_rosenbrock_matches_idas": 18,
    "tests/test_docs_site.py::test_the_site_builds_with_no_warning": 18,
    "tests/test_cli.py::test_simulate_writes_summary_trajectory_scenario_and_plots": 16,
    "tests/test_readme.py::test_readme_api_example_runs_and_agrees_with_the_cli": 15,
    "tests/test_first_hour.py::test_a_run_that_leaves_the_field_keeps_what_it_computed": 15,
    "tests/test_terrain_engine.py::test_one_cell_converges_under_step_refinement": 13,
    "tests/test_terrain_compiled.py::test_grid_code_is_compiled": 13,
    "tests/test_control_grid.py::test_grid_closed_loop_runs_without_failed_solves": 13,
    "tests/test_compiled.py::test_standalone_program_reproduces_python": 11,
    "tests/test_sweep.py::test_grid_sweep_writes_a_row_and_a_run_folder_per_combination": 10,
    "tests/test_control_rti.py::test_ctrl_c_stops_symtrack_mpc": 9,
    "tests/test_control_rti.py::test_compiled_mpc_cached_across_processes[rti-4]": 9,
    "tests/test_simulate.py::test_cvodes_and_idas_match_a_fine_fixed_step_reference": 8,
    "tests/test_control_grid.py::test_grid_plant_continues_a_saved_terrain": 8,
    "tests/test_sweep.py::test_ctrl_c_cancels_the_runs_in_flight_and_keeps_the_finished_ones": 7,
    "tests/test_lateral.py::test_sharp_turn_trajectory_agrees_with_a_64_by_5_quadrature_within_one_percent": 7,
    "tests/test_control_mpc.py::test_closed_loop_straight_offset": 7,
    "tests/test_control_grid.py::test_terrain_in_takes_the_file_geometry": 7,
    "tests/test_sweep.py::test_mpc_sweep_on_a_scheduler_and_workers_started_here": 6,
    "tests/test_first_hour.py::test_ctrl_c_stops_simulate_with_exit_130_and_writes_nothing": 6,
    "tests/test_control_mpc.py::test_plant_with_another_state_layout_needs_x0": 6,
    "tests/test_sweep.py::test_a_killed_worker_has_its_run_redone_on_another": 5,
    # the files added since (issue 10, 12, 13 work; measured at load 4-5, halved as a serial estimate)
    "tests/test_codegen_mpc.py::test_c_closed_loop_agrees_with_python_on_the_uturn": 35,
    "tests/test_soil_map.py::test_the_soil_map_persists_and_a_terrain_keeps_its_own": 19,
    "tests/test_soil_map.py::test_the_wet_headland_example_puts_the_risk_where_the_soil_is_weak": 15,
    "tests/test_soil_map.py::test_each_cell_sinks_by_its_own_soil_and_the_traction_uses_the_soil_under_each_track": 13,
    "tests/test_soil_memory.py::test_multipass_every_pass_adds_less": 12,
    "tests/test_soil_memory.py::test_cycle_law_closed_form_rut_after_n_cycles": 10,
    "tests/test_lane_keeping.py::test_first_pass_leaves_a_rut_pair_at_the_track_gauge": 25,
    "tests/test_grid_standalone.py::test_the_standalone_grid_program_agrees_with_python": 20,
    "tests/test_field_study.py::test_controlled_traffic_counts_against_the_geometry": 10,
    # issue 26 (load 6: 52 + 14 + 10 s; about a third of that on a quiet machine)
    "tests/test_commit_once.py::test_killed_at_8_moments_the_terrain_file_is_as_before_or_advanced_with_a_summary": 20,
    "tests/test_commit_once.py::test_two_writers_of_one_terrain_file_never_mix": 6,
    # issue 38, items 2 and 6 (a quiet machine: the commit's fault injection, the measured memory peaks)
    "tests/test_commit_point.py::test_kill_at_each_commit_step_leaves_old_or_new_and_the_rerun_equals_one_run": 11,
    "tests/test_memory_refusal.py::test_the_estimate_is_within_20_percent_of_the_measured_peak": 11,
    "tests/test_field_study.py::test_ctrl_c_between_a_pass_and_its_record_exits_130_and_keeps_the_passes_done": 7,
    # issue 26 item 2 (load 3: 26 + 25 s, halved as a serial estimate)
    "tests/test_outputs.py::test_the_default_writes_the_figures_read_first_and_the_report_says_what_it_left_out": 13,
    "tests/test_outputs.py::test_all_figures_writes_the_animations_and_every_pass_plots": 12,
    # issue 26 item 3 (load 2-3: 52 + 17 s, halved as a serial estimate)
    "tests/test_quadrature_call.py::test_compiled_rosenbrock_on_a_64x5_rule_gives_the_cvodes_figures": 26,
    "tests/test_quadrature_call.py::test_the_compiled_grid_step_takes_the_call_node_and_equals_the_expanded_one": 9,
}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    if not hasattr(config, "workerinput"):
        return  # a serial run (or xdist's controller): the collection order stays
    cost, first = {}, {}
    for k, item in enumerate(items):
        f = item.nodeid.split("::")[0]
        cost[f] = cost.get(f, 0.0) + SLOW_S.get(item.nodeid, 1.0)
        first.setdefault(f, k)
    # the slowest file first; within a file (and among equals) the collection order
    items.sort(key=lambda it: (-cost[it.nodeid.split("::")[0]], first[it.nodeid.split("::")[0]]))


def two_passes_against_a_continued_pass(d: dict, tmp_path):
    """The scenario document ``d`` (with a [terrain] section) run as two passes in one run, and as
    one pass saved to a terrain file, loaded and driven again: asserts the second equals the
    first run's second pass to the last bit (every storage array, the trajectory and outputs);
    returns (two-pass result, continued result)."""
    import dataclasses

    import numpy as np

    import symtrack
    from symtrack.simulation.scenario import scenario_from_dict
    from symtrack.terrain.settings import settings_from_dict
    from symtrack.terrain.storage import Terrain

    d = dict(d, terrain=dict(d["terrain"], passes=2))
    sc2 = scenario_from_dict(d)
    two = symtrack.simulate(sc2)
    sc1 = dataclasses.replace(sc2, terrain=settings_from_dict(dict(d["terrain"], passes=1)))
    f = tmp_path / "after_pass_1.npz"
    symtrack.simulate(sc1).terrain.save(f)
    again = symtrack.simulate(sc1, terrain=Terrain.load(f))
    for a, b in zip(two.terrain.arrays().values(), again.terrain.arrays().values(), strict=True):
        assert np.array_equal(a, b)  # to the last bit
    assert np.array_equal(two.runs[-1].X, again.runs[0].X) and np.array_equal(two.runs[-1].Y, again.runs[0].Y)
    return two, again
