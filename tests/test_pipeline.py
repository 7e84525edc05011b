"""The run pipeline: the explicit, cached build (a second run of the same model reuses its
model and gives the same figures bit for bit)."""

import time

import numpy as np
import pytest

import symtrack
from symtrack.foundations.errors import ScenarioError
from symtrack.simulation.build import build_cache_info, clear_build_cache, system_model


def test_a_second_build_reuses_the_model_and_runs_the_same():
    clear_build_cache()
    sc = symtrack.load_scenario("validation", {"run.duration_s": 2.0})
    b1 = symtrack.build(sc)
    assert b1.kind == "homogeneous" and build_cache_info() == {"models": 1, "hits": 0, "misses": 1}
    t0 = time.perf_counter()
    r1 = symtrack.simulate(b1)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    r2 = symtrack.simulate(sc)
    second = time.perf_counter() - t0
    assert build_cache_info()["models"] == 1 and build_cache_info()["hits"] >= 2
    assert symtrack.build(sc).model is b1.model
    assert second < first  # the model's construction (most of a short run) is not repeated
    np.testing.assert_array_equal(r1.runs[0].X, r2.runs[0].X)
    np.testing.assert_array_equal(r1.runs[0].Y, r2.runs[0].Y)
    assert {k: v for k, v in r1.summary.items() if "time" not in k} == \
        {k: v for k, v in r2.summary.items() if "time" not in k}


def test_other_model_options_build_another_model():
    sc = symtrack.load_scenario("validation", {"model.traction_sign": "tanh", "run.duration_s": 0.5})
    assert symtrack.build(sc).model is system_model(sc.model)
    assert system_model(sc.model) is not system_model(None)
    assert system_model(sc.model).opts == sc.model


def test_build_checks_the_integrator_and_the_terrain():
    with pytest.raises(ScenarioError):
        symtrack.build("validation", integrator=3)
    with pytest.raises(ScenarioError):
        symtrack.build("validation", terrain="field.npz")
    assert symtrack.build("validation_grid").kind == "grid"
