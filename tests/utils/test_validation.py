"""The one way to check a setting: the value back, or a ValueError naming it and what is allowed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evcd.utils.validation import check_bool, check_choice, check_int, check_real, require


def test_integers():
    assert check_int("n", 3, minimum=1) == 3 and type(check_int("n", np.int64(4))) is int
    assert check_int("k", 0, minimum=0, maximum=2) == 0
    for value, message in (
        (0, "n=0: must be an integer >= 1"),
        (2.5, "n=2.5: must be an integer >= 1"),
        (True, "n=True: must be an integer >= 1"),
        ("3", "n='3': must be an integer >= 1"),
    ):
        with pytest.raises(ValueError, match=f"^{message}$"):
            check_int("n", value, minimum=1)
    with pytest.raises(ValueError, match=r"^k=3: must be an integer in \[0, 2\]$"):
        check_int("k", 3, minimum=0, maximum=2)
    with pytest.raises(ValueError, match=r"^k=3: must be an integer <= 2$"):
        check_int("k", 3, maximum=2)
    with pytest.raises(ValueError, match=r"^k=None: must be an integer$"):
        check_int("k", None)


def test_reals():
    assert check_real("lr", 1e-3, low=0.0, low_open=True) == 1e-3 and check_real("g", 1) == 1.0
    cases = [
        (dict(low=0.0, low_open=True), 0.0, "lr=0.0: must be a finite number > 0"),
        (dict(low=0.0), -1.0, "lr=-1.0: must be a finite number >= 0"),
        (dict(low=0.0, high=1.0), 1.5, r"lr=1.5: must be a finite number in \[0, 1\]"),
        (
            dict(low=0.0, high=1.0, low_open=True, high_open=True),
            1.0,
            r"lr=1.0: must be a finite number in \(0, 1\)",
        ),
        (dict(), math.nan, "lr=nan: must be a finite number"),
        (dict(), math.inf, "lr=inf: must be a finite number"),
        (dict(), True, "lr=True: must be a finite number"),
        (dict(), "x", "lr='x': must be a finite number"),
    ]
    for bounds, value, message in cases:
        with pytest.raises(ValueError, match=f"^{message}$"):
            check_real("lr", value, **bounds)


def test_choices_booleans_and_conditions():
    assert check_choice("loss", "mse", ("mse", "huber")) == "mse"
    with pytest.raises(ValueError, match=r"^loss='l1': must be one of mse, huber$"):
        check_choice("loss", "l1", ("mse", "huber"))
    assert check_bool("double", np.bool_(True)) is True
    with pytest.raises(ValueError, match=r"^double='yes': must be true or false$"):
        check_bool("double", "yes")
    require(True, "never")
    with pytest.raises(ValueError, match=r"^shapes differ$"):
        require(False, "shapes differ")
