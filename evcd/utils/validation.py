"""Checking a setting, written once: each helper returns the value or raises ``ValueError`` naming it.

    lr = check_real("lr", lr, low=0.0, low_open=True)        # "lr=-1: must be a finite number > 0"
    steps = check_int("train.episodes", steps, minimum=0)   # "train.episodes='x': must be an integer >= 0"

Every layer validates its own arguments before anything starts (SUMO, torch), with these helpers,
so that a bad value gets the same kind of message wherever it is given: the name as the user wrote
it, the value, and what is allowed.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Collection
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")
C = TypeVar("C")


def is_integer(value: Any) -> bool:
    """Whether ``value`` is an integer (Python or numpy), booleans excluded."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def is_real(value: Any) -> bool:
    """Whether ``value`` is a finite real number (Python or numpy), booleans excluded."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)


def _range(low: float, high: float, low_open: bool, high_open: bool) -> str:
    if math.isfinite(low) and math.isfinite(high):
        return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    if math.isfinite(low):
        return f"{'>' if low_open else '>='} {low:g}"
    if math.isfinite(high):
        return f"{'<' if high_open else '<='} {high:g}"
    return ""


def check_int(name: str, value: Any, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an ``int`` if it is an integer within ``[minimum, maximum]``.

    Raises:
        ValueError: ``"<name>=<value>: must be an integer >= <minimum>"`` (or the range asked for).
    """
    low = -math.inf if minimum is None else minimum
    high = math.inf if maximum is None else maximum
    if not is_integer(value) or not low <= value <= high:
        bounds = _range(low, high, False, False)
        raise ValueError(f"{name}={value!r}: must be an integer{' ' + bounds if bounds else ''}")
    return int(value)


def check_real(
    name: str,
    value: Any,
    low: float = -math.inf,
    high: float = math.inf,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """``value`` as a ``float`` if it is a finite number within the given bounds.

    Raises:
        ValueError: ``"<name>=<value>: must be a finite number > 0"`` (or the range asked for).
    """
    ok = is_real(value)
    if ok:
        ok = (value > low if low_open else value >= low) and (value < high if high_open else value <= high)
    if not ok:
        bounds = _range(low, high, low_open, high_open)
        raise ValueError(f"{name}={value!r}: must be a finite number{' ' + bounds if bounds else ''}")
    return float(value)


def check_choice(name: str, value: T, choices: Collection[Any]) -> T:
    """``value`` if it is one of ``choices``.

    Raises:
        ValueError: ``"<name>=<value>: must be one of a, b, c"``.
    """
    if value not in choices:
        raise ValueError(f"{name}={value!r}: must be one of {', '.join(map(str, choices))}")
    return value


def require(condition: bool, message: str) -> None:
    """Raise ``ValueError(message)`` unless ``condition``: for checks of structure (shapes, states)
    rather than of one value."""
    if not condition:
        raise ValueError(message)


def check_bool(name: str, value: Any) -> bool:
    """``value`` if it is a boolean (Python or numpy).

    Raises:
        ValueError: ``"<name>=<value>: must be true or false"``.
    """
    if not isinstance(value, bool | np.bool_):
        raise ValueError(f"{name}={value!r}: must be true or false")
    return bool(value)


def with_overrides(owner: str, config_cls: type[C], config: Any, overrides: dict[str, Any]) -> C:
    """``config`` (an instance of the dataclass ``config_cls``, or ``None`` for its defaults) with the
    fields named in ``overrides`` replaced (the dataclass checks the values).

    Raises:
        ValueError: an override that is not a field (naming it, ``owner`` and the fields), or a
            ``config`` of another type.
    """
    fields = [f.name for f in dataclasses.fields(config_cls)]
    unknown = sorted(set(overrides) - set(fields))
    if unknown:
        raise ValueError(f"{owner}: unknown hyperparameters {unknown}; {config_cls.__name__} has {fields}")
    if config is not None and not isinstance(config, config_cls):
        raise ValueError(f"config={config!r}: must be a {config_cls.__name__}")
    config = config if config is not None else config_cls()
    return dataclasses.replace(config, **overrides) if overrides else config
