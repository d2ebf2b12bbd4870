"""Data sets: the thrown-bottle throws of Sec. 5.1."""

from fnnlib.data.bottle import BOTTLE_FILES, THROW_SOURCES, DataError, Throws, bottle_throws, load_bottle, synthetic_throws

__all__ = ["BOTTLE_FILES", "THROW_SOURCES", "DataError", "Throws", "bottle_throws", "load_bottle", "synthetic_throws"]
