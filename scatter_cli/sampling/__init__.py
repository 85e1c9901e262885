"""Surface -> points: the sample plan and its random stream (``plan``), the warps, the
methods and weightings, and one source interface (``sources``) for every way a run makes its
points; Poisson-disk thinning (``poisson``), stable placement (``stable``) and the exterior
filter (``exterior``) are sources built on those."""
