"""The in-memory caches behind one registry (symtrack.foundations.caches): each bounded, the model
libraries included (they hold their models, so the bound frees them), and symtrack.clear_caches()
empties them all."""

import dataclasses
import gc
import weakref

import pytest

import symtrack
from symtrack.foundations import caches
from symtrack.model.options import ModelOptions
from symtrack.native import cache as native_cache
from symtrack.simulation import builder


def test_a_bounded_cache_keeps_the_most_recently_used():
    c = caches.BoundedCache("toy", 2)
    c.put("a", 1)
    c.put("b", 2)
    assert c.get("a") == 1  # a hit moves it to the end
    c.put("c", 3)  # drops b, the least recently used
    assert "b" not in c and c.get("a") == 1 and c.get("c") == 3 and len(c) == 2
    assert c.get_or_build("d", lambda: 4) == 4 and len(c) == 2
    with pytest.raises(ValueError, match="at least 1"):
        caches.BoundedCache("toy", 0)


def test_many_models_keep_the_caches_bounded_and_clear_caches_empties_them(monkeypatch):
    """Twelve different small models, each built and its library taken: the model and library caches
    stay at their limits, the models they dropped are freed, and clear_caches() empties every cache."""
    symtrack.clear_caches()
    monkeypatch.setattr(builder.MODELS, "max_entries", 3)
    monkeypatch.setattr(native_cache.LIBRARIES, "max_entries", 3)
    refs = []
    for n in range(12):
        opts = dataclasses.replace(ModelOptions(), lateral_law="creep", gauss_points=2, lateral_segments=1 + n)
        model = builder.system_model(opts)
        native_cache.library(model, compiled=False)
        refs.append(weakref.ref(model))
        del model
        info = symtrack.cache_info()
        assert info["models"]["entries"] <= 3 and info["model_libraries"]["entries"] <= 3
    gc.collect()
    alive = sum(r() is not None for r in refs)
    assert alive <= 3, f"{alive} of 12 models still alive with the caches holding at most 3"
    assert all(v["max_entries"] is None or v["entries"] <= v["max_entries"] for v in symtrack.cache_info().values())
    symtrack.clear_caches()
    assert all(v["entries"] == 0 for v in symtrack.cache_info().values())
    gc.collect()
    assert all(r() is None for r in refs)
