"""Field checks shared by the frozen orientation value types."""

from __future__ import annotations

import math

from apygis.errors import OrientationError

__all__ = ["finite_fields"]


def finite_fields(obj, names, prefix: str = "", show_value: bool = False) -> None:
    """Turn the fields ``names`` of the frozen dataclass ``obj`` into finite floats.

    Raises :class:`OrientationError` ``"<prefix><name> must be a number"`` or
    ``"... must be finite"`` (with ``", got <value>"`` if ``show_value``); an
    integer too large for a double is "not finite" (no ``OverflowError``).
    """
    for name in names:
        value = getattr(obj, name)
        try:
            v = float(value)
        except OverflowError:  # an int beyond a double (float(10**400))
            raise OrientationError(f"{prefix}{name} must be finite, got a huge integer") from None
        except (TypeError, ValueError):
            got = f", got {value!r}" if show_value else ""
            raise OrientationError(f"{prefix}{name} must be a number{got}") from None
        if not math.isfinite(v):
            got = f", got {v!r}" if show_value else ""
            raise OrientationError(f"{prefix}{name} must be finite{got}")
        object.__setattr__(obj, name, v)
