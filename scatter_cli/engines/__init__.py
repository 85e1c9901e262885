"""Many meshes at once: ``scatter batch`` and its worker processes, locally or as Dask tasks."""
