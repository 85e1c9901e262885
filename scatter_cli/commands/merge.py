"""``scatter merge``: join point files of one format and one column layout into one.

The shards of a run (``--shard K/M``), joined in order, give that run's bytes: every
mergeable format is a header that carries the count, then the points as rows, so the
joined file is the header written for the total count followed by each part's rows.
Which formats merge is the format table's ``mergeable``; each part is read by its
format's reader (:mod:`scatter_cli.writers.pointfiles`), the one ``preview`` reads it with.
"""

from __future__ import annotations

import os

from ..errors import ScatterError, ScatterUsageError
from ..writers import MERGEABLE, check_extra, infer_format, open_output


def merge(parts, output, fmt=None):
    """Join the point files ``parts`` (in order) into ``output``; returns the point count.

    The format is ``fmt``, else that of the parts' suffix (they must all have it);
    ``output`` must be of that format too.
    """
    paths = [os.fspath(p) for p in parts]
    if not paths:
        raise ScatterUsageError("merge needs at least one part")
    for p in paths + ([] if output is None or str(output) == "-" else [os.fspath(output)]):
        if os.path.isdir(p):
            raise ScatterError(f"{p}: is a directory (merge joins point files)")
    formats = [_format(p, fmt) for p in paths]
    for p, f in zip(paths, formats):
        if f != formats[0]:
            raise ScatterError(f"{p}: a {f.upper()} file, not {formats[0].upper()} like {paths[0]}")
    kind = formats[0]
    if output is not None and str(output) != "-" and _format(output, fmt) != kind:
        raise ScatterUsageError(f"{output}: the parts are {kind.upper()}, the output must be too")
    check_extra(kind)
    from ..writers.pointfiles import read_file  # NumPy: imported once there is work

    files = []
    for p in paths:
        file = read_file(p, kind)
        if files and file.layout != files[0].layout:
            raise ScatterError(f"{p}: columns or types differ from {paths[0]} ({_describe(file.layout)} "
                               f"against {_describe(files[0].layout)})")
        files.append(file)
    with open_output(output) as stream:
        files[0].join(files, stream)
    return sum(f.count for f in files)


def _format(path, fmt):
    """The format of ``path`` (or ``fmt``) among those merge joins; the error offers those."""
    try:
        return infer_format(path, fmt, choices=MERGEABLE)
    except ScatterUsageError as exc:
        unknown = exc
    try:
        known = infer_format(path, fmt)
    except ScatterUsageError:
        raise unknown from None
    raise ScatterUsageError(f"merge cannot join {known.upper()} files (it joins: {', '.join(MERGEABLE)})")


def _describe(layout):
    return str(layout)[:200]
