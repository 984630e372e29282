"""apygis: photogrammetric map revision (APY) and aerotriangulation (PHODIS AT).

The public API::

    import apygis

    m = apygis.MapFile("ZH1091", scale=5000, crs="EPSG:2056")
    roads = m.layer("r")
    nums = roads.add_line([(2600000.0, 1200000.0, 410.0), (2600050.0, 1200010.0, 411.5)], code=12)
    apygis.write(m, "out/ZH1091")            # native APY binary, one file per layer
    m2 = apygis.read("out/ZH1091")

The names are imported on first use (PEP 562), so that ``import apygis`` is
cheap and a command that needs only the orientation code does not load the
map model or the drivers.
"""

from __future__ import annotations

import importlib
import logging

from apygis.errors import (
    ApygisError,
    CapacityError,
    DriverError,
    FileOverwriteError,
    FormatError,
    RecordNotFoundError,
    TopologyError,
    ValueRangeError,
)

_LAZY = {
    "MapFile": "apygis.model.map",
    "Layer": "apygis.model.map",
    "read": "apygis.formats",
    "write": "apygis.formats",
    "drivers": "apygis.formats",
}

__all__ = [
    "ApygisError",
    "CapacityError",
    "DriverError",
    "FileOverwriteError",
    "FormatError",
    "Layer",
    "MapFile",
    "RecordNotFoundError",
    "TopologyError",
    "ValueRangeError",
    "drivers",
    "read",
    "write",
]

logging.getLogger(__name__).addHandler(logging.NullHandler())


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'apygis' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))


try:
    from importlib.metadata import version as _version

    __version__ = _version("apygis")
except Exception:  # running from a source tree that was never installed
    __version__ = "0+unknown"
