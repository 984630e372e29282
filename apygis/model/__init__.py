"""The map model: layers of symbols, line points and texts, and their topology."""

from apygis.model.map import Layer, MapFile

__all__ = ["Layer", "MapFile"]
