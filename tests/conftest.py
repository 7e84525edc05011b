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

# Files compiled at other levels than the ones above (the level is part of a compiled artefact's cache key:
# an artefact another file built at another level is built once more, not replaced). Measured on empty
# caches, CPU of the file run alone at the two levels:
# - the terrain engine at -O0 where the files run their engines for seconds, not minutes (gcc's time is most
#   of such a file's; with their engine-building neighbours: test_grid3d 48 / 83 s at -O0 / -O1,
#   test_moisture 7 / 15 s, test_soil_law 13 / 15 s, test_terrain_engine 74 / 80 s, test_vehicle_registry
#   9.9 / 10.6 s; alone: test_soil_map 22 / 41 s, test_vehicle3d_report 16 / 22 s, test_gis 11 / 23 s,
#   test_vehicle_step_replay (since its replay runs 34 s of the recording) 25.5 / 32.7 s; test_docs_site, whose
#   site build runs the gallery's examples for seconds each (docs/gallery_examples.py; second_pass_3d alone
#   7.9 / 14.6 s));
# - the other generated code at -O1 in test_operations.py, whose MPC functions and grid steps run for the
#   minutes of simulated field work (165 s at -O0, 141 s at -O1).
FILE_OPT_LEVELS = {
    **{name: ("SYMTRACK_TUNED_OPT_LEVEL", "0") for name in ("test_gis.py", "test_grid3d.py", "test_moisture.py",
                                                          "test_soil_law.py", "test_soil_map.py",
                                                          "test_terrain_engine.py", "test_vehicle3d_report.py",
                                                          "test_vehicle_registry.py", "test_vehicle_step_replay.py",
                                                          "test_docs_site.py")},
    "test_operations.py": ("SYMTRACK_OPT_LEVEL", "1"),
}


@pytest.fixture(autouse=True, scope="module")
def _file_opt_level(request):
    """The module's optimisation level of FILE_OPT_LEVELS for its tests, its module fixtures (an autouse fixture
    is set up before the others of its scope) and the processes they start."""
    level = FILE_OPT_LEVELS.get(request.path.name)
    if level is None:
        yield
        return
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv(*level)
        yield


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
# is idle). SLOW_S are the seconds of the slowest tests (setup + call) in a whole run on 2 cores
# (--durations=60 of the fast and the slow set, each scaled to its unloaded wall time): an ordering hint
# only; a test not listed counts as 1 s.
SLOW_S = {
    "tests/test_operations.py::test_season_4ha_reduced_writes_its_summary_and_animation": 40,
    "tests/test_grid3d.py::test_an_elevation_raster_of_a_plane_gives_the_analytic_side_slope": 45,
    "tests/test_vehicle_step_replay.py::test_the_controlled_vehicle_step_carries_what_the_uncontrolled_one_diverges_on": 40,  # noqa: E501
    "tests/test_terrain_pool_passes.py::test_two_passes_equal_one_pass_save_load_and_a_second_pass": 28,
    "tests/test_traffic_sweep.py::test_a_traffic_sweep_missing_a_system_resumes_to_the_same_table": 18,
    "tests/test_quadrature_call.py::test_compiled_rosenbrock_on_a_64x5_rule_gives_the_cvodes_figures": 26,
    "tests/test_terrain_pool.py::test_pool_and_brute_force_give_the_same_vehicle_motion": 18,
    "tests/test_terrain_examples.py::test_bench_terrain_quick": 14,
    "tests/test_moisture.py::test_moisture_raster_uniform_equals_single_value_and_split": 39,
    "tests/test_codegen_mpc.py::test_c_closed_loop_agrees_with_python_on_the_uturn[shear]": 37,
    "tests/test_vehicle3d_raster.py::test_the_compiled_rosenbrock_takes_the_raster": 35,
    "tests/test_terrain_engine.py::test_pool_equals_one_channel_per_cell_and_brute_force": 20,
    "tests/test_tracks_wheels.py::test_arvidsson_2011_tracks_about_duals_below_singles": 17,
    "tests/test_grid3d.py::test_a_second_pass_rides_in_the_ruts_of_the_first": 22,
    "tests/test_region_check.py::test_fast_agrees_with_full_on_operation_small": 11,
    "tests/test_vehicle_registry.py::test_the_toy_runs_on_the_terrain_engine": 22,
    "tests/test_scenario_mutation.py::test_mutated_document_is_a_scenario_or_a_clear_error": 21,
    "tests/test_control_grid.py::test_engine_plant_is_the_default_and_matches_idas": 11,
    "tests/test_examples.py::test_compaction_reference_on_the_small_field": 20,
    "tests/test_control_grid.py::test_grid_plant_with_the_compiled_rosenbrock_matches_idas": 14,
    "tests/test_codegen_mpc.py::test_c_closed_loop_agrees_with_python_on_the_uturn[creep]": 19,
    "tests/test_terrain_engine.py::test_one_cell_converges_under_step_refinement": 7,
    "tests/test_region_dask.py::test_the_folder_table_maps_and_report": 18,
    "tests/test_soil_law.py::test_a_toy_law_on_the_terrain_engine_and_its_terrain_file": 18,
    "tests/test_operations.py::test_polygon_operation_driven_on_clay": 17,
    "tests/test_soil_law.py::test_a_toy_law_on_a_soil_map": 17,
    "tests/test_region_dask.py::test_a_rerun_skips_the_finished_and_redoes_the_rest_bit_for_bit": 16,
    "tests/test_physics_fuzz.py::test_3d_at_rest_across_a_side_slope_stays_bounded_on_the_fixed_step": 16,
    "tests/test_terrain_compiled.py::test_grid_rosenbrock_matches_idas": 16,
    "tests/test_grid3d.py::test_flat_virgin_field_matches_the_homogeneous_3d_run": 16,
    "tests/test_control_mpc3d.py::test_the_3d_closed_loop_keeps_the_line_along_a_side_slope": 15,
    "tests/test_simulate.py::test_cvodes_and_idas_match_a_fine_fixed_step_reference": 4,
    "tests/test_control_examples.py::test_jit_build_runs": 5,
    "tests/test_region_dask.py::test_a_killed_client_then_a_rerun_gives_the_uninterrupted_outputs": 15,
    "tests/test_default_law.py::test_the_standalone_programs_run_the_default_law": 15,
    "tests/test_terrain_engine.py::test_cells_in_lanes_equal_one_cell_at_a_time": 14,
    "tests/test_terrain_engine.py::test_engine_matches_idas_on_a_small_field": 10,
    "tests/test_control_shear.py::test_shear_law_closed_loop_into_the_u_turn_on_clay": 13,
    "tests/test_vehicle3d.py::test_flat_ground_reproduces_the_planar_validation_on_the_shear_law": 12,
    "tests/test_operations.py::test_k_turn_driven_on_clay": 12,
    "tests/test_quadrature_call.py::test_the_compiled_grid_step_takes_the_call_node_and_equals_the_expanded_one": 6,
    "tests/test_operations.py::test_the_mpc_drives_a_small_operation_on_clay": 9,
    "tests/test_operations.py::test_field_persists_bit_for_bit_through_save_and_load": 7,
    "tests/test_newcomer.py::test_an_mpc_resolved_scenario_holds_every_model_option_and_the_version": 11,
    "tests/test_front_door.py::test_each_field_operation_starting_file_runs_as_written[season]": 11,
    "tests/test_control_rti.py::test_rti_iterates_converge_to_the_converged_nmpc[creep-0.7-60]": 10,
    "tests/test_physics_fuzz.py::test_a_random_plausible_scenario_keeps_every_property": 9,
    "tests/test_control_mpc3d.py::test_the_3d_straight_offset_approach_without_failed_solves": 9,
    "tests/test_control_grid.py::test_grid_closed_loop_runs_without_failed_solves": 9,
    "tests/test_region_dask.py::test_a_killed_worker_loses_no_field_season": 9,
    "tests/test_memory_refusal.py::test_the_estimate_is_within_20_percent_of_the_measured_peak": 9,
    "tests/test_soil_memory.py::test_cycle_law_closed_form_rut_after_n_cycles": 2,
    "tests/test_vehicle_registry.py::test_the_toy_is_chosen_by_model_vehicle_on_every_homogeneous_integrator[rosenbrock]": 9,  # noqa: E501
    "tests/test_quadrature_call.py::test_the_mapped_sum_and_its_jacobian_equal_the_expanded_ones[shear_quasistatic-local]": 9,  # noqa: E501
    "tests/test_commit_point.py::test_kill_at_each_commit_step_leaves_old_or_new_and_the_rerun_equals_one_run": 9,
    "tests/test_sweep.py::test_mpc_sweep_on_a_scheduler_and_workers_started_here": 9,
    "tests/test_vehicle3d_report.py::test_a_3d_terrain_study_writes_them_per_pass": 9,
    "tests/test_front_door.py::test_each_starting_file_runs_as_written[mpc]": 9,
    "tests/test_control_rti.py::test_compiled_mpc_cached_across_processes[ipopt-1]": 8,
    "tests/test_commit_once.py::test_killed_at_8_moments_the_terrain_file_is_as_before_or_advanced_with_a_summary": 8,
    "tests/test_engine_fmu.py::test_fmpy_cosimulation_is_the_python_engine_run": 8,
    "tests/test_quadrature_call.py::test_the_compiled_twin_has_its_own_cache_key_and_matches_the_expanded_model": 8,
    "tests/test_control_rti.py::test_rti_on_the_lagged_shear_law_relinearises_the_rejected_step": 6,
    "tests/test_soil_map.py::test_each_cell_sinks_by_its_own_soil_and_the_traction_uses_the_soil_under_each_track": 8,
    "tests/test_sweep.py::test_a_killed_worker_has_its_run_redone_on_another": 7,
    "tests/test_front_door.py::test_each_field_operation_starting_file_runs_as_written[operation]": 7,
    "tests/test_sweep.py::test_a_failing_run_is_recorded_and_a_rerun_redoes_only_it": 7,
    "tests/test_control_mpc3d.py::test_the_quasi_static_hull_is_the_trim_s_hull_on_a_side_slope": 7,
    "tests/test_sweep.py::test_a_lost_scheduler_ends_the_sweep_with_a_message_and_a_rerun_resumes": 7,
    "tests/test_lateral_transient.py::test_sharp_turn_on_sandy_loam_agrees_with_a_64_by_5_quadrature_within_one_percent": 7,  # noqa: E501
    "tests/test_simulate.py::test_the_default_shear_law_turns_the_crawler_where_the_papers_creep_law_does_not": 7,
    "tests/test_control_mpc3d.py::test_no_nan_in_the_mpc_s_derivatives_for_the_3d_vehicle": 7,
    "tests/test_fmu.py::test_the_coast_case_is_within_two_percent_of_cvodes": 6,
    "tests/test_towed.py::test_turn_the_axle_cuts_inside": 6,
    "tests/test_vehicle3d_report.py::test_a_3d_run_writes_its_figures_and_a_planar_run_does_not": 6,
    "tests/test_simulate.py::test_validation_meets_the_reported_figures": 6,
    "tests/test_fmu.py::test_fmpy_validation_finds_no_problem": 6,
    "tests/test_quadrature_call.py::test_cvodes_and_idas_with_a_large_quadrature_build_the_expanded_form": 6,
    "tests/test_soil_law.py::test_a_toy_law_through_a_scenario": 6,
    "tests/test_operations.py::test_operation_small_meets_the_tracking_target[sandy_loam_15]": 6,
    "tests/test_terrain_world.py::test_assignment_invariants": 5,
    "tests/test_sweep.py::test_a_killed_worker_of_the_local_cluster_is_forked_anew_and_its_run_redone": 5,
    "tests/test_wheeled.py::test_pass_against_the_footprint_and_turned": 5,
    "tests/test_towed.py::test_table_against_the_direct_sum": 5,
    "tests/test_newcomer.py::test_result_and_terrain_show_what_they_are_and_column_names_each_once": 5,
    "tests/test_vehicle3d_raster.py::test_a_plane_s_raster_runs_as_the_analytic_plane": 5,
    "tests/test_quadrature_call.py::test_the_mapped_sum_and_its_jacobian_equal_the_expanded_ones[shear]": 5,
    "tests/test_control_rti.py::test_rti_iterates_converge_to_the_converged_nmpc[shear-0.95-150]": 5,
    "tests/test_physics_fuzz.py::test_3d_at_rest_on_a_ramp_of_heavy_clay_settles": 5,
    "tests/test_field_study.py::test_a_killed_study_resumes_from_its_last_checkpoint": 5,
    "tests/test_vehicle_registry.py::test_toy_vehicle_runs_through_cvodes_and_keeps_its_own_equations": 5,
    "tests/test_docs_site.py::test_the_site_builds_with_no_warning": 42,
    "tests/test_region_check.py::test_the_tracked_columns_compression_is_bounded_by_the_rut": 5,
    "tests/test_control_mpc.py::test_mpc_cli": 5,
    "tests/test_control_examples.py::test_timing_comparison_rows": 3,
    "tests/test_control_mpc.py::test_closed_loop_straight_offset": 4,
    "tests/test_control_mpc.py::test_plant_with_another_state_layout_needs_x0": 4,
    "tests/test_physics_fuzz.py::test_the_checks_catch_a_fixed_step_run_without_error_control": 4,
    "tests/test_field_study.py::test_a_rerun_resumes_an_interrupted_study_and_gives_the_uninterrupted_result": 4,
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
