"""Typed method options, one deadline per call, and the box enlargement the 3D methods share.

Every method registered with :func:`stability.api.register` declares a frozen dataclass of
options (a subclass of :class:`MethodOptions`). :func:`stability.solve` builds it once from
its keyword arguments with :meth:`MethodOptions.of`: an unknown name or a value of the
wrong type is a :class:`~stability.errors.MethodError` that lists the valid options with
their types and defaults; a value of the right type out of its range is a
:class:`~stability.errors.GraspError` naming the option and its range
(:meth:`MethodOptions.check`). The method then receives the options and one
:class:`Deadline`, started when ``solve`` called it, that every inner solve reads its time
left from.
"""

from __future__ import annotations

import math
import time
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

import numpy as np

from .errors import GraspError, MethodError

__all__ = [
    "BOX_RETRIES",
    "Deadline",
    "MethodOptions",
    "check_ranges",
    "enlarge_box",
    "finite",
]

BOX_RETRIES = 2  # tenfold enlargements of a method's box, at most, per call

_O = TypeVar("_O", bound="MethodOptions")
_S = TypeVar("_S")


@dataclass(frozen=True)
class Deadline:
    """The end of a method call's time budget: ``limit`` seconds after ``start`` (a
    ``time.perf_counter()`` reading); ``limit=None`` is no limit."""

    limit: float | None
    start: float = field(default_factory=time.perf_counter)

    def remaining(self) -> float | None:
        """Seconds left [s]: None without a limit, 0 once passed."""
        if self.limit is None:
            return None
        return max(0.0, self.start + self.limit - time.perf_counter())

    def expired(self) -> bool:
        """The limit has passed (never without a limit)."""
        left = self.remaining()
        return left is not None and left <= 0.0

    def at(self) -> float | None:
        """The deadline as a ``time.perf_counter()`` reading (None: no limit)."""
        return None if self.limit is None else self.start + self.limit


def finite(v: Any) -> bool:
    """``v`` converts to a finite float."""
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def _conforms(value: Any, hint: Any) -> bool:
    """``value`` has the type ``hint`` names: ``float`` takes any real number but a bool,
    ``int`` an integer but a bool, ``bool`` a bool, ``tuple[X, ...]`` a tuple or list of
    ``X``; unions any of theirs."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_conforms(value, h) for h in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if hint is Any:
        return True
    if hint is bool:
        return isinstance(value, bool | np.bool_)
    if hint is int:
        return isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)
    if hint is float:
        return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
            value, bool | np.bool_
        )
    if origin is tuple:
        item = typing.get_args(hint)[0]
        return isinstance(value, tuple | list) and all(_conforms(v, item) for v in value)
    if isinstance(hint, type):
        return isinstance(value, hint)
    return True


def _type_name(hint: Any) -> str:
    return getattr(hint, "__name__", None) or str(hint).replace("typing.", "")


@dataclass(frozen=True)
class MethodOptions:
    """A method's options: subclasses are frozen dataclasses whose fields are the options,
    with their range checks in :meth:`check`. A field ``time_limit`` [s] (None: no limit)
    bounds the whole method call (:meth:`deadline`)."""

    @classmethod
    def valid(cls) -> str:
        """The valid options, one ``name: type = default`` each, for error messages."""
        hints = typing.get_type_hints(cls)
        return ", ".join(f"{f.name}: {_type_name(hints[f.name])} = {f.default!r}"
                         for f in fields(cls))  # fmt: skip

    @classmethod
    def of(cls: type[_O], method: str, options: dict[str, Any]) -> _O:
        """The options ``solve(..., method=method, **options)`` asked for, checked: an
        unknown name or a wrongly typed value is a :class:`MethodError` listing the valid
        options; a value out of range a :class:`GraspError` (:meth:`check`)."""
        hints = typing.get_type_hints(cls)
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(options) - names)
        if unknown:
            raise MethodError(f"unknown option(s) {unknown} for method {method!r}; its options: "
                              f"{cls.valid()}")  # fmt: skip
        for name, value in options.items():
            if not _conforms(value, hints[name]):
                raise MethodError(
                    f"option {name}={value!r} of method {method!r} must be "
                    f"{_type_name(hints[name])}; its options: {cls.valid()}"
                )
        return cls(**options)

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """:class:`GraspError` naming the first option out of its range."""
        t = getattr(self, "time_limit", None)
        if t is not None and not (finite(t) and t >= 0):
            raise GraspError(f"time_limit must be finite and >= 0 s, got {t!r}")

    def deadline(self) -> Deadline:
        """A :class:`Deadline` ``time_limit`` seconds from now (none without one)."""
        t = getattr(self, "time_limit", None)
        return Deadline(None if t is None else float(t))


def check_ranges(opts: object, ranges: dict[str, tuple[bool, str]]) -> None:
    """:class:`GraspError` for the first ``name`` whose ``(ok, range)`` is not ok, naming
    the range the option must lie in."""
    for name, (ok, where) in ranges.items():
        if not ok:
            raise GraspError(f"{name} must be {where}, got {getattr(opts, name)!r}")


def enlarge_box(
    attempt: Callable[[float, _S | None], tuple[_S, str | None]],
    factor: float,
    deadline: Deadline,
    keep: Callable[[_S, _S], str | None],
    retries: int = BOX_RETRIES,
) -> tuple[_S, list[str]]:
    """Solve in a box of ``factor`` times the force scale, enlarged tenfold at most
    ``retries`` times (:data:`BOX_RETRIES`) while the answer shows the box cut it off.

    ``attempt(factor, previous)`` solves in the box of ``factor`` (``previous``: the last
    answer, None at first) and returns the answer and why the box may have cut it off
    (None: it did not; the answer stands). ``keep(previous, answer)``, asked of every
    answer in a larger box, returns why the previous answer is kept instead (a time-out,
    an error) or None to go on with the new one. Returns the answer and one line per
    enlargement; with no time left for an enlargement the last answer stands.
    """
    notes: list[str] = []
    prev, cut = attempt(factor, None)
    for _ in range(retries):
        if cut is None:
            break
        notes.append(f"bound_factor {factor:g}: {cut}")
        factor *= 10.0
        if deadline.expired():
            notes.append(f"bound_factor {factor:g}: no time left")
            break
        sol, cut = attempt(factor, prev)
        why = keep(prev, sol)
        if why is not None:
            notes.append(f"bound_factor {factor:g}: {why}; the answer of bound_factor "
                         f"{factor / 10:g} is kept")  # fmt: skip
            break
        prev = sol
    return prev, notes
