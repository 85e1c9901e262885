"""``--exterior``: the surface that can be seen from outside, by rays (Embree) and by
faces certainly enclosed."""
