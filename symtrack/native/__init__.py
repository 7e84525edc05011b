"""Native code: what is generated as C from the symbolic model (:mod:`.generate`, the
Rosenbrock step builders :mod:`.rosenbrock` and :mod:`.grid_rosenbrock`) and the model
libraries (:mod:`.cache`: the generated Functions compiled through :mod:`symtrack.toolchain` and loaded
with ``casadi.external``)."""
