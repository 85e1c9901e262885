"""A benchmark's command line and work folder, so that each benchmark states only its options."""

from __future__ import annotations

import argparse
import contextlib
import tempfile
from pathlib import Path

KEEP = "keep the generated files here (default: a temporary directory)"


def options(**defaults):
    """Parse the command line: one `--name` per keyword (underscores as dashes) of its default's
    type. A default of False makes a flag, None an optional string; a (default, help) pair adds
    help. `dir` is the folder that keeps generated inputs (see work_folder)."""
    ap = argparse.ArgumentParser()
    for name, default in defaults.items():
        default, text = default if isinstance(default, tuple) else (default, KEEP if name == "dir" else None)
        flag = "--" + name.replace("_", "-")
        if default is False:
            ap.add_argument(flag, action="store_true", help=text)
        elif default is None:
            ap.add_argument(flag, help=text)
        else:
            ap.add_argument(flag, type=type(default), default=default, help=text)
    return ap.parse_args()


@contextlib.contextmanager
def work_folder(keep=None):
    """Yield (inputs, scratch): the folder for generated inputs (`keep`, made if missing, or the
    scratch folder) and a temporary scratch folder for outputs, removed afterwards."""
    with tempfile.TemporaryDirectory() as tmp:
        inputs = Path(keep or tmp)
        inputs.mkdir(parents=True, exist_ok=True)
        yield inputs, Path(tmp)
