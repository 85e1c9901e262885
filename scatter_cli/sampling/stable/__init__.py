"""``--stable``: points keyed to the faces themselves, as per-face Poisson arrivals."""
