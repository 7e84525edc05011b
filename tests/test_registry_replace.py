"""A registry entry replaced under its name (a plug-in edited and registered again in a notebook) is
what the next run builds: the in-memory caches found by the name (the models of a set of options)
are emptied when another entry takes the name, and kept when the same entry is registered again."""

from test_soil_law import LinearPlastic

from symtrack.foundations import caches
from symtrack.foundations.errors import SymtrackError
from symtrack.foundations.registry import Registry
from symtrack.model.options import ModelOptions
from symtrack.simulation.builder import system_model
from symtrack.soil import law as soil_law


class TwiceAsStiff(LinearPlastic):
    """The toy law edited: twice the loading stiffness, registered under the toy's name."""

    def virgin_pressure(self, z, law):
        return 2 * law[0] * z


def test_a_soil_law_replaced_under_its_name_is_the_one_the_next_model_is_built_with():
    soil_law.register(LinearPlastic)
    try:
        first = system_model(ModelOptions(soil_law=LinearPlastic.name))
        assert type(first.terrain.law) is LinearPlastic
        soil_law.register(TwiceAsStiff, replace=True)
        second = system_model(ModelOptions(soil_law=LinearPlastic.name))
        assert type(second.terrain.law) is TwiceAsStiff and second is not first
        soil_law.unregister(LinearPlastic.name)  # removed, then the first registered again
        soil_law.register(LinearPlastic)
        assert type(system_model(ModelOptions(soil_law=LinearPlastic.name)).terrain.law) is LinearPlastic
    finally:
        soil_law.unregister(LinearPlastic.name)


def test_registering_the_same_entry_again_keeps_the_caches():
    menu = Registry("a thing", "thing", SymtrackError)
    store = caches.cache("test_registry_replace", 2)
    entry, other = object(), object()
    menu.add("a", entry)
    store.put("model of a", 1)
    menu.remove("a")
    menu.add("a", entry)  # the same entry again (a test fixture's register/unregister)
    assert "model of a" in store
    menu.add("a", other, replace=True)  # another entry under the name
    assert "model of a" not in store
