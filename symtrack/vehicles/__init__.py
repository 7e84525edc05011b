"""The vehicles: each machine's model and its ground parts (docs/model.md; docs/vehicle3d.md;
docs/subsoil.md, "Wheeled machines").

- :mod:`.registry`: the vehicle-model menu (``[model] vehicle``) and how a vehicle plugs in;
- :mod:`.planar`: the planar tracked vehicle (``"planar"``, and ``"planar_lateral"`` with the
  lateral shear states), its tracks' pressure distribution and shear;
- :mod:`.vehicle3d`: the 3D tracked vehicle (``"3d"``), a rigid hull that heaves, pitches and rolls
  on the ground's shape;
- :mod:`.tyre`: a tyre's contact area and the stress it gives at depth (Keller 2005);
- :mod:`.wheeled`: a wheeled machine's pass over a field;
- :mod:`.towed`: a towed load on one axle following the crawler (``[terrain.towed]``).
"""
