"""Built-in sensor-to-segment trees (YAML). Load with ``SensorTree.preset(name)``.

Axes are OpenSim's (Rajagopal 2015 model): x anterior, y superior, z right; left-side
axial vectors are mirrored as ``(-x, -y, z)``. Offsets and lengths [m] are a generic adult
skeleton, used only to draw the body and to write BVH.
"""
