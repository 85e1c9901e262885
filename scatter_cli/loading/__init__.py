"""Mesh files -> :class:`~scatter_cli.surface.model.Surface`: the loader table (``load``), the
fast readers for plain jobs, USD stages and Draco-compressed glTF, input path checks."""
