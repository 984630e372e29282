"""Source layers of a foreign file -> map layers: the one rule of every reader.

A DXF or OGR file has layers of its own (``ROADS``, ``0``, ``Gewässer``);
a map's layers are extensions of 1-3 letters. :class:`LayerNames` maps each
source layer to a map layer, in this order:

1. ``layer_map`` (option, CLI ``--layer-map ROADS=r,WATER=h``): the named
   map layer, or none (``-`` or empty: the source layer is skipped). Names
   compare without regard to case. A name in ``layer_map`` that the file
   does not have is refused (:meth:`LayerNames.check_used`), so that a typing
   error is not silently ignored.
2. A source layer named like an extension (1-3 letters, ``r`` or ``R``) maps
   to itself in lower case: how apygis's own layers come back.
3. Every other source layer gets a map layer of its own, named from it
   (accents dropped, lower case): the first three letters of its name
   (``ROADS`` -> ``roa``, ``Gewässer`` -> ``gew``), else, when another
   source layer (or rule 1 or 2) already has that name, the first letters
   of its words (``LEICA_DISTO_3D`` -> ``ldd``, ``Land-Use Zones`` ->
   ``luz``); then, and for names without letters (``0``), the next free
   one of ``x``, ``y``, ``z``, ``xa``, ..., ``xz``, ``ya``, ... The source
   layers are named in the order given (a file's layer table order).

>>> names = LayerNames({"WATER": "h"}, ["0", "ROADS", "roadside", "Water", "R", "Gewässer"])
>>> [names(n) for n in ("0", "ROADS", "roadside", "water", "r", "Gewässer")]
['x', 'roa', 'y', 'h', 'r', 'gew']
>>> names = LayerNames(None, ["LEICA_DISTO_ID", "LEICA_DISTO_3D", "LEICA_DISTO_POINT_ENTITY"])
>>> names.mapping()
{'LEICA_DISTO_ID': 'lei', 'LEICA_DISTO_3D': 'ldd', 'LEICA_DISTO_POINT_ENTITY': 'ldp'}
"""

from __future__ import annotations

import re
import string
import unicodedata
from collections.abc import Iterable, Iterator, Mapping

from apygis.errors import DriverError
from apygis.model.map import check_ext

__all__ = ["LayerNames", "fallback_exts", "parse_layer_map"]


def parse_layer_map(value) -> dict[str, str | None]:
    """A layer map from a dict or from the CLI form ``"ROADS=r,WATER=h"``.

    Keys are source layer names (kept as given; compared without regard to
    case); values are layer extensions (1-3 letters), or ``None`` / ``"-"``
    / ``""`` to skip the source layer.

    >>> parse_layer_map("ROADS=R, WATER=h, Defpoints=-")
    {'ROADS': 'r', 'WATER': 'h', 'Defpoints': None}
    """
    if value is None:
        return {}
    if isinstance(value, str):
        items = []
        for part in value.split(","):
            if not part.strip():
                continue
            name, sep, ext = part.rpartition("=")
            if not sep or not name.strip():
                raise DriverError(
                    f"layer map: expected LAYER=ext pairs separated by commas, not {part.strip()!r}"
                )
            items.append((name.strip(), ext.strip()))
    elif isinstance(value, Mapping):
        items = list(value.items())
    else:
        raise DriverError(f"layer map: a dict or a string 'A=x,B=y', not {value!r}")
    out: dict[str, str | None] = {}
    for name, ext in items:
        if not isinstance(name, str) or not name:
            raise DriverError(f"layer map: a source layer name is a string, not {name!r}")
        if ext is None or ext in ("", "-"):
            out[name] = None
            continue
        try:
            out[name] = check_ext(ext)
        except ValueError as exc:
            raise DriverError(f"layer map: {name}={ext}: {exc}") from None
    return out


def fallback_exts(taken: Iterable[str]) -> Iterator[str]:
    """``x``, ``y``, ``z``, ``xa``, ..., ``xz``, ``ya``, ... less those in ``taken``."""
    taken = set(taken)
    first = ["x", "y", "z"]
    more = [a + b for a in "xyz" for b in string.ascii_lowercase]
    more += [a + b + c for a in "xyz" for b in string.ascii_lowercase for c in "abcdefghij"]
    for e in first + more:
        if e not in taken:
            yield e


def _candidates(name: str) -> list[str]:
    """Names for a source layer by rule 3, best first."""
    plain = unicodedata.normalize("NFKD", name).lower()
    letters = "".join(c for c in plain if c in string.ascii_lowercase)
    words = re.findall(r"[a-z0-9]+", "".join(c for c in plain if c.isascii()))
    initials = "".join(next((c for c in w if c.isalpha()), "") for w in words)
    out = [letters[:3]]
    if len(words) > 1:
        out.append(initials[:3])
    return [c for c in out if c]


class LayerNames:
    """Source layer name -> map layer extension, or None (skipped); see the module docstring.

    ``sources`` are the source layers known before reading (a DXF's layer
    table, an OGR dataset's layers), in order; a name met later gets its
    map layer by the same rule when first asked for.
    """

    def __init__(self, layer_map=None, sources: Iterable[str] = (), where=None):
        self.where = f"{where}: " if where else ""
        self.map = parse_layer_map(layer_map)
        self._upper = {k.upper(): v for k, v in self.map.items()}
        self._ext: dict[str, str | None] = {}  # upper-case source name -> ext
        self.shown: dict[str, str] = {}  # upper-case source name -> name as first met
        self._taken: set[str] = {e for e in self.map.values() if e}
        sources = list(sources)
        self._taken |= {f for f in map(self._fixed, sources) if f}
        self._fallback = fallback_exts(())
        for s in sources:
            self(s)

    def _fixed(self, name: str) -> str | None:
        """The map layer of rules 1 and 2, or None."""
        up = name.upper()
        if up in self._upper:
            return self._upper[up] or ""
        if 1 <= len(name) <= 3 and all(c in string.ascii_letters for c in name):
            return name.lower()
        return None

    def _free(self) -> str:
        for e in self._fallback:
            if e not in self._taken:
                return e
        raise DriverError("more source layers than map layer names")  # pragma: no cover

    def __call__(self, name: str) -> str | None:
        up = name.upper()
        if up in self._ext:
            return self._ext[up]
        fixed = self._fixed(name)
        if fixed is not None:
            ext: str | None = fixed or None
        else:
            free = [c for c in _candidates(name) if c not in self._taken]
            ext = free[0] if free else self._free()
        if ext:
            self._taken.add(ext)
        self._ext[up] = ext
        self.shown.setdefault(up, name)
        return ext

    def mapping(self) -> dict[str, str | None]:
        """Every source layer met so far (as first written) -> its map layer (None: skipped)."""
        return {self.shown[k]: v for k, v in self._ext.items()}

    def check_used(self, present: Iterable[str]) -> None:
        """Refuse ``layer_map`` names that are not among the file's layers ``present``."""
        have = {p.upper() for p in present}
        unknown = [k for k in self.map if k.upper() not in have]
        if unknown:
            listed = ", ".join(sorted(set(present), key=str.upper)) or "none"
            raise DriverError(
                f"{self.where}layer map names {', '.join(repr(u) for u in unknown)}, which the "
                f"file does not have (its layers: {listed})"
            )

    def select(self, wanted, present: Iterable[str], groups=None) -> set[str] | None:
        """The upper-case source layers to read (None: all); unknown ``wanted`` are refused.

        ``groups`` maps other names (the map layer ``r`` of apygis's own
        OGR layers ``r_lines``, ...) to the source layers they stand for.
        """
        if wanted is None:
            return None
        wanted = [wanted] if isinstance(wanted, str) else list(wanted)
        have = {p.upper(): p for p in present}
        groups = {str(k).upper(): v for k, v in (groups or {}).items()}
        out: set[str] = set()
        unknown = []
        for w in wanted:
            key = str(w).upper()
            if key in have:
                out.add(key)
            elif key in groups:
                out |= {g.upper() for g in groups[key]}
            else:
                unknown.append(w)
        if unknown:
            listed = ", ".join(sorted(have.values(), key=str.upper)) or "none"
            extra = sorted(k.lower() for k in groups if k not in have)
            also = f"; map layers {', '.join(extra)}" if extra else ""
            raise DriverError(
                f"{self.where}no layer {', '.join(repr(u) for u in unknown)} in the file "
                f"(its layers: {listed}{also})"
            )
        return out

    def groups(self, names: Iterable[str]) -> dict[str, list[str]]:
        """Map layer -> the source layers among ``names`` that become it (for ``select``)."""
        out: dict[str, list[str]] = {}
        for n in names:
            ext = self(n)
            if ext is not None:
                out.setdefault(ext, []).append(n)
        return out
