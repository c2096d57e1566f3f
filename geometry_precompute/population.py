"""Populations of simulated users (reference/model, "Simulated users"): a distribution in
place of a number for a numeric user setting, drawn once per rollout.

A population setting is a table with one key::

    user_noise = {uniform = [0.0, 0.4]}       # uniform on [low, high]
    user_switch = {normal = [0.2, 0.1]}       # N(mean, sd^2) truncated to the setting's range
    user_tremor = {values = [0.0, 0.01, 0.02]}  # one of the values, each as likely

Each rollout draws its own value from the counter-based stream that keys its other random
numbers (seed, scene, task, start: ``shacc_jax.streams``), so a rollout is the same user in
every mode and in every batch. The drawn values are in the rollout table.

This module reads and checks the tables (one-line errors naming the field and the rule) and
encodes them as the bake's arrays (:func:`encode`); the draw itself is JAX's
(``shacc_jax.populations.population_values``). Plain Python: no JAX, no NumPy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from .errors import InputError, shown

# The numeric user settings that take a population, in the order of the bake's arrays.
POPULATED = ("user_noise", "user_noise_tau", "user_tremor", "user_tremor_hz", "user_switch",
             "user_switch_at", "user_mode_switch_s")
DISTRIBUTIONS = ("uniform", "normal", "values")
# Codes in the bake (``user_dist``): 0 is a plain number (the setting's own leaf).
FIXED, UNIFORM, NORMAL, VALUES = range(4)
MAX_VALUES = 16  # entries of a ``values`` list (a static size of the bake's arrays)
ARGS = 4         # numbers per distribution in ``user_dist_args``


@dataclass(frozen=True)
class Population:
    """One setting's distribution: ``kind`` (``uniform``, ``normal`` or ``values``) and its
    numbers (``uniform``: low, high; ``normal``: mean, sd; ``values``: the values).

    >>> Population("uniform", (0.0, 0.4)).text()
    'uniform(0, 0.4)'
    """

    kind: str
    numbers: tuple[float, ...]

    def text(self) -> str:
        """The canonical text (the sweep tables' ``set.NAME`` column)."""
        return f"{self.kind}({', '.join(f'{v:g}' for v in self.numbers)})"

    def to_json(self) -> dict[str, list[float]]:
        """The table as written in a settings file."""
        return {self.kind: list(self.numbers)}


def is_table(value: Any) -> bool:
    return isinstance(value, Mapping | Population)


def text_of(value: Any) -> str | None:
    """A setting's raw value (a number, a population table, None for the default) as the
    sweep tables' text: a population's :meth:`Population.text`, a number by ``%g``.

    >>> text_of({"values": [0, 0.01]}), text_of(0.2), text_of(None)
    ('values(0, 0.01)', '0.2', None)
    """
    if value is None:
        return None
    if isinstance(value, Population):
        return value.text()
    if isinstance(value, Mapping):
        kind, numbers = next(iter(value.items()))
        return Population(kind, tuple(float(v) for v in numbers)).text()
    return f"{float(value):g}"


def parse(value: Any, in_range, rule: str, source: str, field: str) -> Population:
    """A population table checked: one known key, finite numbers, each in the setting's
    range (``in_range``, ``rule`` its text); ``normal``'s mean in the range and sd > 0.

    >>> parse({"uniform": [0, 0.5]}, lambda x: 0 <= x <= 1, "must be in [0, 1]", "s", "f")
    Population(kind='uniform', numbers=(0.0, 0.5))
    """
    if isinstance(value, Population):
        value = value.to_json()
    if len(value) != 1 or next(iter(value)) not in DISTRIBUTIONS:
        raise InputError(source, field, "a population is a table with one key of "
                         f"{', '.join(DISTRIBUTIONS)} (e.g. {{uniform = [0, 0.4]}}), got "
                         f"{shown(dict(value))}")
    kind, numbers = next(iter(value.items()))
    where = f"{field}.{kind}"
    if not isinstance(numbers, list | tuple) or not all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in numbers):
        raise InputError(source, where, f"must be a list of numbers, got {shown(numbers)}")
    if not all(math.isfinite(v) for v in numbers):
        raise InputError(source, where, "must hold finite numbers (no NaN or inf)")
    nums = tuple(float(v) for v in numbers)
    if kind == "values":
        if not 1 <= len(nums) <= MAX_VALUES:
            raise InputError(source, where, f"must hold 1 to {MAX_VALUES} values, got "
                             f"{len(nums)}")
        inside = nums
    else:
        if len(nums) != 2:
            what = "[low, high]" if kind == "uniform" else "[mean, sd]"
            raise InputError(source, where, f"must be two numbers {what}, got {shown(numbers)}")
        if kind == "uniform":
            if nums[0] > nums[1]:
                raise InputError(source, where, f"must be [low, high] with low <= high, got "
                                 f"{shown(numbers)}")
            inside = nums
        else:
            if not nums[1] > 0:
                raise InputError(source, where, f"the sd must be > 0, got {nums[1]:g}")
            inside = nums[:1]
    for v in inside:
        if not in_range(v):
            raise InputError(source, where, f"{rule.replace('must be', 'each value must be')}"
                             f", got {v:g}")
    return Population(kind, nums)


def encode(value: Any, lo: float, hi: float) -> tuple[int, list[float], list[float]]:
    """A setting's value as the bake's (code, args (ARGS,), values (MAX_VALUES,)); a plain
    number is (FIXED, zeros, zeros). ``lo``, ``hi``: the setting's range, the normal
    distribution's truncation (a draw is clipped into it as well)."""
    args, values = [0.0] * ARGS, [0.0] * MAX_VALUES
    if not isinstance(value, Population):
        return FIXED, args, values
    n = value.numbers
    if value.kind == "uniform":
        return UNIFORM, [n[0], n[1], n[0], n[1]], values
    if value.kind == "normal":
        return NORMAL, [n[0], n[1], lo, hi], values
    values[:len(n)] = n
    return VALUES, [float(len(n)), 0.0, 0.0, 0.0], values
