"""Parameter ranges of the scene families and the draws made from them, recorded for provenance.

A family declares a dict ``name -> range``; every parameter it uses is drawn through
:class:`Draws`, so the ranges a reader sees (``FAMILIES[name].ranges``, the report's table) are the
ranges the code draws from, and the values drawn for one seed are kept in the sequence's ``meta``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Choice", "Draws", "Int", "LogUniform", "Uniform", "describe_ranges"]


@dataclass(frozen=True)
class Uniform:
    """A float uniform in ``[lo, hi]``."""

    lo: float
    hi: float

    def draw(self, rng):
        return float(rng.uniform(self.lo, self.hi)) if self.hi > self.lo else float(self.lo)

    def __str__(self):
        return f"{self.lo:g}" if self.hi == self.lo else f"U({self.lo:g}, {self.hi:g})"


@dataclass(frozen=True)
class LogUniform:
    """A float whose logarithm is uniform in ``[log lo, log hi]`` (a dose spanning a decade)."""

    lo: float
    hi: float

    def draw(self, rng):
        return float(math.exp(rng.uniform(math.log(self.lo), math.log(self.hi))))

    def __str__(self):
        return f"logU({self.lo:g}, {self.hi:g})"


@dataclass(frozen=True)
class Int:
    """An integer uniform in ``[lo, hi]`` (both included)."""

    lo: int
    hi: int

    def draw(self, rng):
        return int(rng.integers(self.lo, self.hi + 1))

    def __str__(self):
        return f"{self.lo}" if self.hi == self.lo else f"{self.lo}..{self.hi}"


@dataclass(frozen=True)
class Choice:
    """One of ``options``, each equally likely."""

    options: tuple

    def draw(self, rng):
        return self.options[int(rng.integers(len(self.options)))]

    def __str__(self):
        return "{" + ", ".join(str(o) for o in self.options) + "}"


class Draws:
    """Draw named parameters from a family's ranges with one generator; remember what was drawn.

    Parameters
    ----------
    rng : numpy.random.Generator
    ranges : dict
        ``name -> Uniform | LogUniform | Int | Choice``.
    """

    def __init__(self, rng: np.random.Generator, ranges: dict):
        self.rng = rng
        self.ranges = ranges
        #: name -> value drawn, in the order drawn
        self.params: dict = {}
        #: names of the values derived from others (:meth:`record`), not drawn from a range
        self.derived: set = set()

    def __call__(self, name: str):
        try:
            r = self.ranges[name]
        except KeyError:
            raise KeyError(f"parameter {name!r} has no range in this family") from None
        v = r.draw(self.rng)
        self.params[name] = v
        return v

    def record(self, name: str, value):
        """Keep a derived value (not drawn from a range) with the drawn ones."""
        self.params[name] = value
        self.derived.add(name)
        return value


def describe_ranges(ranges: dict) -> str:
    """``name range; ...`` on one line (the report's table)."""
    return "; ".join(f"{k} {v}" for k, v in ranges.items())
