"""``--crs``: the coordinate system a LAS/LAZ file records, as OGC WKT.

``EPSG:N`` becomes WKT through pyproj (WKT1 as GDAL writes it, what LAS 1.4 readers
expect); a WKT text is checked by pyproj and recorded as given. Anything else is a usage
error. Imports pyproj only when a coordinate system is given.
"""

from __future__ import annotations

import re

from ..errors import ScatterError, ScatterUsageError

EPSG = re.compile(r"\s*EPSG\s*:\s*(\d+)\s*", re.IGNORECASE)


def _pyproj():
    try:
        import pyproj
    except ImportError:
        raise ScatterError("--crs needs pyproj: pip install pyproj") from None
    return pyproj


def crs_wkt(value: str) -> str:
    """The OGC WKT of the ``--crs`` value ``EPSG:N`` or WKT."""
    pyproj = _pyproj()
    code = EPSG.fullmatch(value)
    try:
        if code:
            return pyproj.CRS.from_epsg(int(code.group(1))).to_wkt(pyproj.enums.WktVersion.WKT1_GDAL)
        pyproj.CRS.from_wkt(value)
    except pyproj.exceptions.CRSError:
        what = f"EPSG:{code.group(1)} is not a coordinate system pyproj knows" if code else "neither EPSG:N nor WKT"
        raise ScatterUsageError(f"--crs {_short(value)}: {what}") from None
    return value.strip()


def _short(value):
    return repr(value if len(value) <= 40 else value[:37] + "...")
