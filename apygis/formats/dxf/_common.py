"""Names and constants shared by the DXF writer and readers."""

from __future__ import annotations

import logging
import re

log = logging.getLogger("apygis.formats.dxf")

APPID = "APYGIS"
"""The registered application name of apygis's XDATA and objects dictionary."""
FORMAT_NAME = "apygis-dxf"
FORMAT_VERSION = 1
BLOCK_PREFIX = "APY_SYM_"
"""Symbol blocks are named ``APY_SYM_NN`` (NN: the code, two digits)."""
SYMBOL_SIZE_MM = 3.0
"""Width of a symbol (its 15x15 grid) on paper at the map's scale, in mm."""
TEXT_HEIGHT_MM = 2.5
"""Height of texts, spot-height labels and attributes on paper, in mm."""
DEFAULT_SCALE = 1000
"""The scale denominator the sizes are computed for when a map has no scale."""
DXF_VERSIONS = {"R2010": "AC1024", "R2013": "AC1027", "R2018": "AC1032"}

_GRID = 15
_CHUNK = 250  # characters per string tag of the header record
_BINARY_SENTINEL = b"AutoCAD Binary DXF\r\n\x1a\x00"
_BLOCK_RE = re.compile(rf"^{BLOCK_PREFIX}([0-9][0-9])$", re.IGNORECASE)
_CTRL = re.compile("[\x00-\x1f\x7f-\x9f]")
_ENTITIES_START = "\n  2\nENTITIES\n"
_ENTITIES_END = "  0\nENDSEC\n"
_CURVE_TYPES = ("ARC", "CIRCLE", "ELLIPSE", "SPLINE")
