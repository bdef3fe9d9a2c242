"""Option checks: a value that makes no sense fails at once with a ValueError naming the option,
the value and the valid range (the benchmark turns it into "error: planner 'label': <message>"
before any episode runs). Every comparison is written so that NaN fails it."""

from __future__ import annotations

import math
import numbers


def require(condition: bool, message: str) -> None:
    """ValueError(message) unless `condition`."""
    if not condition:
        raise ValueError(message)


def check_int(name: str, value, minimum: int = 1, maximum: int | None = None, note: str = "") -> None:
    """ValueError unless `value` is a whole number in minimum..maximum (no upper bound when None).

    `note` (e.g. "0 = off") is added to the message after the range.
    """
    whole = isinstance(value, numbers.Integral) or (isinstance(value, float) and value.is_integer())
    ok = whole and value >= minimum and (maximum is None or value <= maximum)
    rule = f">= {minimum}" if maximum is None else f"in {minimum}..{maximum}"
    if not whole:
        rule = f"an integer {rule}"
    shown = value if isinstance(value, numbers.Real) and not isinstance(value, bool) else repr(value)
    require(ok, f"{name} must be {rule}{f' ({note})' if note else ''}, got {shown}")


def check_number(
    name: str,
    value,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    none: str | None = None,
    allow_inf: bool = False,
    note: str = "",
) -> None:
    """ValueError unless `value` is a real number in the interval from `low` to `high`
    (closed ends unless `low_open` / `high_open`; None: unbounded on that side).

    NaN is always refused, +-inf unless `allow_inf` (the interval still applies). `none`, when
    given, says what None means, and None is then accepted; `note` is added to the message.
    """
    if value is None and none is not None:
        return
    number = isinstance(value, numbers.Real) and not isinstance(value, bool)
    v = float(value) if number else math.nan
    ok = number and not math.isnan(v) and (allow_inf or math.isfinite(v))
    ok = ok and (low is None or (v > low if low_open else v >= low))
    ok = ok and (high is None or (v < high if high_open else v <= high))
    if low is not None and high is not None:
        rule = f"a number in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    else:
        rule = "a number" if allow_inf else "a finite number"
        if low is not None:
            rule += f" {'>' if low_open else '>='} {low:g}"
        if high is not None:
            rule += f" {'<' if high_open else '<='} {high:g}"
    notes = "; ".join(n for n in (note, f"None = {none}" if none is not None else "") if n)
    shown = value if number else repr(value)
    require(ok, f"{name} must be {rule}{f' ({notes})' if notes else ''}, got {shown}")
