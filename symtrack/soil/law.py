"""The soil law as an object, and the menu of laws (a registry, as the integrators' one).

A soil law is what a terrain cell's soil does under load: the reaction pressure p(z; history)
and its slope dp/dz, the history update after a step (the world manager's INFO_OUT), the
increment a new stay of a cell may add (INFO_IN), the work per metre to press a rut (the
homogeneous terrain's compaction resistance) and the sinkage at which the virgin law carries a
pressure (the static start guess). Everything is written in CasADi, so the same expressions reach
the symbolic models, the channel pool and the terrain engine's generated C.

The law declares its own coefficients (:attr:`SoilLaw.params`, each a
:class:`~symtrack.foundations.params.ParamSpec` with its unit, range, default and source): a
model on the law has them in its parameter set and its parameter vector, a scenario's
``[soil]`` table takes them, with no edit outside the law's module
(:func:`symtrack.model.parameters.model_params`). The law owns its law vector:
:meth:`SoilLaw.vector` builds it from a mapping of the model's parameter names (numbers, or the
model's parameter symbols), :meth:`SoilLaw.values` as numbers, :meth:`SoilLaw.symbols` as a
symbol of its own (the channel Functions' ``law`` input). Nothing outside this module knows its
length or the meaning of its entries.

The history a law reads is the cell's stored history (the world manager keeps it, the channel
fields of :mod:`symtrack.terrain.channels` carry it), :data:`HISTORY_NAMES`: z_max, p_max (the
top of the virgin loading met), z_off (the plastic sinkage of earlier load cycles), delta (the
increment this stay may add) and d_c (what it has added so far). A law that has no cycles
leaves the last three alone.

The law of a model is its option ``model.soil_law`` (:class:`~symtrack.model.options.ModelOptions`);
the default, ``"bekker_wong"``, is :class:`BekkerWong`. Adding a law is one class and one
:func:`register` call::

    class LinearPlastic(SoilLaw):
        name = "linear_plastic"
        ...
    register(LinearPlastic)
"""

from __future__ import annotations

import abc
from collections.abc import Mapping

import casadi as ca

from ..foundations.errors import ParameterError
from ..foundations.params import param
from ..foundations.registry import Registry
from . import cell

__all__ = ["BekkerWong", "DEFAULT", "HISTORY_NAMES", "REGISTRY", "SoilLaw", "get", "make", "names", "register",
           "unregister"]

# the cell history every law reads, in the order of its ``hist`` argument (module doc)
HISTORY_NAMES = ("z_max_m", "p_max_Pa", "z_off_m", "cycle_increment_m", "cycle_progress_m")


class SoilLaw(abc.ABC):
    """A soil law (module doc). Subclasses set :attr:`name`, :attr:`params` (the declarations of
    the coefficients the law brings), :attr:`param_names` (the model parameters :meth:`vector`
    reads: its own and any other of the model's) and :attr:`vector_names` (the entries of the law
    vector) and
    write the abstract methods; ``hist`` is a sequence of the :data:`HISTORY_NAMES` (a CasADi
    vector or a tuple), ``law`` the law vector (symbolic, or a sequence of floats and symbols: a law
    may specialise its expressions to the entries given as numbers, as the terrain engine's copies of
    :attr:`engine_specialisations` want).

    Parameters
    ----------
    opts : ModelOptions
        The model's options (a law may read its numerical options, e.g. the Bekker
        regularisation cap).
    """

    name: str = ""
    description: str = ""
    params: tuple = ()
    param_names: tuple[str, ...] = ()
    vector_names: tuple[str, ...] = ()
    # values of law-vector entries (a dict of vector_names entry -> number per copy) for which the terrain
    # engine compiles a specialised copy of pressure_and_slope beside the general one, that entry given to
    # it as a float (a law may then write a faster form of the same numbers); a soil whose law vector has
    # those values runs the copy, chosen at run time
    engine_specialisations: tuple[dict[str, float], ...] = ()

    def __init__(self, opts):
        self.opts = opts

    @property
    def size(self) -> int:
        """The length of the law vector."""
        return len(self.vector_names)

    def symbols(self, name: str = "law") -> ca.SX:
        """The law vector as a symbol of its own (an input of the channel Functions)."""
        return ca.SX.sym(name, self.size)

    @abc.abstractmethod
    def vector(self, params: Mapping):
        """The law vector from ``params`` (parameter name -> number or CasADi expression)."""

    def values(self, params: Mapping) -> list[float]:
        """The law vector as floats, from a numeric parameter dict."""
        v = self.vector({k: float(params[k]) for k in self.param_names})
        return [float(x) for x in ca.DM(ca.evalf(v)).full().ravel()]

    def named(self, law) -> dict:
        """The entries of a law vector by name (:attr:`vector_names`)."""
        return {k: law[i] for i, k in enumerate(self.vector_names)}

    @abc.abstractmethod
    def virgin_pressure(self, z, law):
        """The pressure [Pa] of the virgin (never loaded) soil at sinkage z [m]."""

    @abc.abstractmethod
    def pressure(self, z, hist, law):
        """The reaction pressure p(z; history) [Pa]."""

    @abc.abstractmethod
    def pressure_and_slope(self, z, hist, law):
        """(p [Pa], dp/dz [Pa/m]): the pressure and its slope written piece by piece (the terrain
        engine's Newton iterations)."""

    @abc.abstractmethod
    def history_update(self, z, p, hist, law):
        """INFO_OUT: (z_max', p_max', d_c', plastic, phase) after a step that ended at sinkage z
        with reaction pressure p; ``plastic`` 1 when the stay deformed the soil plastically (it
        then counts as a load cycle), ``phase`` 1 on the virgin branch, else 2."""

    @abc.abstractmethod
    def cycle_increment(self, z, hist, cycles, law, beta):
        """INFO_IN: the plastic increment delta [m] a cell's new stay may add, for a cell at
        sinkage z with ``cycles`` load cycles; ``beta`` the soil's repeated-loading exponent."""

    @abc.abstractmethod
    def compaction_work(self, z, law, width):
        """The work per metre [N] a track of width ``width`` [m] spends pressing virgin soil to a
        rut of depth z [m] (the homogeneous terrain's compaction resistance)."""

    @abc.abstractmethod
    def static_sinkage(self, p, law):
        """The sinkage [m] at which the virgin law carries the pressure p [Pa] (its inverse; the
        static start guess)."""


_BEKKER = "Bekker's pressure-sinkage law (Bekker 1969, in Wong, Theory of Ground Vehicles)"
_WONG_UNLOADING = "Wong, Theory of Ground Vehicles: the response to repetitive loading (docs/model.md)"


class BekkerWong(SoilLaw):
    """Bekker's virgin loading, Wong's unloading/reloading line and the cycle law of
    :mod:`symtrack.soil.cell` (docs/model.md, "Pressure-sinkage"); the mathematics lives there.

    Law vector: k_eq = k_c / b + k_phi [N/m^(n+2)], n, the elastic stiffness K_e [Pa/m], kappa
    (the unloading-stiffness floor) and the regularisation length d [m] of the Bekker term
    (:func:`~symtrack.soil.cell.bekker_regularisation_length`: its bias's length capped at the model option
    ``bekker_regularisation_m``, and at least the length that bounds the law's slope by
    ``cell.BEKKER_SLOPE_OVER_ELASTIC_MAX`` times K_e).
    """

    name = "bekker_wong"
    description = "Bekker loading, Wong unloading/reloading line, plastic load cycles (docs/model.md)"
    params = (
        param("bekker_n", "Bekker sinkage exponent n", 0.0, 3.0, False, source=_BEKKER),
        param("k_c_N_per_m_n1", "Bekker cohesive modulus k_c [N/m^(n+1)]", 0.0, 1e9, source=_BEKKER),
        param("k_phi_N_per_m_n2", "Bekker frictional modulus k_phi [N/m^(n+2)]", 0.0, 1e12, source=_BEKKER),
        param("elastic_stiffness_Pa_per_m", "unloading/reloading stiffness K_e (Chrono SCM's elastic stiffness)",
              0.0, 1e12, False, source=_WONG_UNLOADING),
        param("unloading_stiffness_floor", "kappa: the unloading slope is at least kappa * p_max / z_max",
              1.0, 100.0, source=_WONG_UNLOADING),
    )
    param_names = ("k_c_N_per_m_n1", "k_phi_N_per_m_n2", "track_width_m", "bekker_n", "elastic_stiffness_Pa_per_m",
                   "unloading_stiffness_floor")
    vector_names = ("k_eq", "n", "elastic_stiffness_Pa_per_m", "kappa", "regularisation_m")
    # the terrain engine's copy for n = 0.5 (pressure_and_slope's sqrt form; the presets' clays)
    engine_specialisations = ({"n": 0.5},)

    def vector(self, params):
        keq = cell.k_eq(params["k_c_N_per_m_n1"], params["k_phi_N_per_m_n2"], params["track_width_m"])
        n = params["bekker_n"]
        return ca.vertcat(keq, n, params["elastic_stiffness_Pa_per_m"], params["unloading_stiffness_floor"],
                          cell.bekker_regularisation_length(keq, n, self.opts.bekker_regularisation_m,
                                                          params["elastic_stiffness_Pa_per_m"]))

    def virgin_pressure(self, z, law):
        return cell.bekker_pressure(z, law[0], law[1], law[4])

    def pressure(self, z, hist, law):
        return cell.reaction_pressure(z, hist[0], hist[1], law[0], law[1], law[2], law[3], law[4], z_off=hist[2],
                                      delta=hist[3], d_c=hist[4])

    def pressure_and_slope(self, z, hist, law):
        """With a numeric n = 0.5 the Bekker term k z+ (z+ + d)^(n-1) is written k z+ / sqrt(z+ + d)
        (the same number; libm's pow is about 20 x slower than sqrt)."""
        keq, n, reg_m = law[0], law[1], law[4]
        if isinstance(n, float) and n == 0.5:
            def bekker(zz):
                zp = ca.fmax(zz, 0)
                sq = ca.sqrt(zp + reg_m)
                # k (z+ / 2 + d) / (z+ + d)^(3/2): the general slope k (n z+ + d) (z+ + d)^(n-2) at n = 1/2
                return keq * zp / sq, ca.if_else(zz > 0, keq * (0.5 * zp + reg_m) / ((zp + reg_m) * sq), 0)
        else:
            bekker = None
        return cell.reaction_pressure_and_slope(z, hist[0], hist[1], keq, n, law[2], law[3], reg_m, z_off=hist[2],
                                                delta=hist[3], d_c=hist[4], bekker=bekker)

    def history_update(self, z, p, hist, law):
        return cell.history_update(z, p, hist[0], hist[1], hist[2], hist[3], hist[4], law[2], law[3], law[4])

    def cycle_increment(self, z, hist, cycles, law, beta):
        return cell.cycle_increment(z, hist[0], hist[1], hist[2], cycles, law[2], law[3], law[4], beta)

    def compaction_work(self, z, law, width):
        """Bekker's b k_eq z^(n+1) / (n+1) (reconstruction)."""
        n = law[1]
        return width * law[0] * z ** (n + 1) / (n + 1)

    def static_sinkage(self, p, law):
        """Bekker's z = (p / k_eq)^(1/n) (the unregularised law)."""
        return (p / law[0]) ** (1 / law[1])


_MENU: Registry[type[SoilLaw]] = Registry("a soil law", "model.soil_law", ParameterError)
REGISTRY = _MENU.entries
DEFAULT = BekkerWong.name


def register(law: type[SoilLaw], replace: bool = False) -> type[SoilLaw]:
    """Add a law to the menu (``model.soil_law`` accepts its name from then on)."""
    if not (isinstance(law, type) and issubclass(law, SoilLaw) and law.name):
        raise ValueError(f"{law!r} is not a named SoilLaw subclass")
    return _MENU.add(law.name, law, replace)


unregister = _MENU.remove
names = _MENU.names


def get(name: str, where: str = "model.soil_law") -> type[SoilLaw]:
    """The class of ``name``; an unknown name is a :class:`ParameterError` listing the menu."""
    return _MENU.get(name, where)


def make(opts) -> SoilLaw:
    """The law of the model options ``opts`` (their ``soil_law``), set up with them."""
    return get(opts.soil_law)(opts)


register(BekkerWong)
