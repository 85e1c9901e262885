"""A compiled kernel of another checkout, loaded beside this one's: for the benchmarks
that call the kernels of two builds in turn (edge_kernels.py, reader_kernels.py)."""

import importlib.util
from pathlib import Path

from scatter_cli.core.native import KERNELS


def kernel_of(checkout, name, tag):
    """Kernel ``name`` (as native.KERNELS names it) built in place in ``checkout``, loaded as
    the module ``tag.name``, apart from this checkout's."""
    folder = Path(checkout).joinpath(*KERNELS[name].package.split("."))
    spec = importlib.util.spec_from_file_location(f"{tag}.{name}", next(folder.glob(f"{name}*.so")))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
