"""Native code: what is generated as C from the symbolic model (:mod:`.generate`, the
Rosenbrock step builders :mod:`.rosenbrock` and :mod:`.grid_rosenbrock`) and the one
compile-and-cache API (:mod:`.cache`: hash-keyed shared libraries loaded with
``casadi.external``), used by every part of symtrack that compiles, and by ``codegen/``."""
