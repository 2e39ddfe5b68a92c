"""A config key's declaration: a dataclass field whose metadata holds its help and checks (what
``chorjax config keys``, the flags that set it and the docs' reference show), and the check of a value given
for one (from a file, an override, a flag or a saved calibration)."""

from __future__ import annotations

import dataclasses
import difflib
import math
import typing
from collections.abc import Callable, Sequence
from typing import Any

from chorjax.errors import UserError


def config_field(
  default,
  help: str,
  choices: Sequence | Callable[[], Sequence] | None = None,
  minimum: float | None = None,
  resumable: bool = False,
  below: float | None = None,
  more: str | None = None,
  maximum: float | None = None,
  **extra,
) -> Any:
  """A config field: its default, help text (one or two lines: ``chorjax config keys`` and the flags that set
  it show it) and checks; ``more``: what the docs' reference says besides (the reasoning, the measurements).
  ``choices`` of a list field apply to each of its elements; ``resumable`` keys may change when a run is
  continued without --force (e.g. to train longer); ``below``: an exclusive upper bound, ``maximum`` an
  inclusive one; ``extra``: more metadata (a sampling control's record)."""
  meta = {
    "help": help,
    "more": more,
    "choices": choices if callable(choices) else tuple(choices) if choices else None,
    "minimum": minimum,
    "below": below,
    "maximum": maximum,
    "resumable": resumable,
    **extra,
  }
  if isinstance(default, (list, tuple)):
    return dataclasses.field(default_factory=lambda: tuple(default), metadata=meta)
  return dataclasses.field(default=default, metadata=meta)


def field_choices(meta, registered: bool = True) -> tuple | None:
  """A field's allowed values (``meta``: its metadata); a callable's are read now (the families, with those
  registered in this process where ``registered``)."""
  choices: Any = meta.get("choices")
  if callable(choices):
    return tuple(typing.cast(Sequence, choices(registered)))
  return tuple(choices) if choices else None


def suggest(key: str, options: Sequence[str]) -> str:
  """ "; did you mean 'x'?" for the closest of ``options``, or ""."""
  close = difflib.get_close_matches(key, options, n=1, cutoff=0.5)
  return f"; did you mean {close[0]!r}?" if close else ""


def _short(value: Any) -> str:
  """``repr(value)``, cut to 60 characters: an error line names the value, it does not reprint a huge one."""
  text = repr(value)
  return text if len(text) <= 60 else text[:57] + "..."


def check_value(where: str, key: str, field: dataclasses.Field, hint: type, value: Any):
  """``value`` converted to the field's type ``hint``, or a UserError naming ``key`` and ``where`` it came from
  (type, finite, choices, range)."""
  meta = field.metadata
  if hint is bool:
    ok = isinstance(value, bool)
  elif hint is int:
    ok = isinstance(value, int) and not isinstance(value, bool)
  elif hint is float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    value = float(value) if ok else value
  elif hint is str:
    ok = isinstance(value, str)
  elif hint is tuple:
    ok = isinstance(value, (list, tuple)) and all(isinstance(v, (str, int)) and not isinstance(v, bool) for v in value)
    value = tuple(value) if ok else value
  else:  # pragma: no cover - schema error
    raise TypeError(hint)
  if not ok:
    tname = "list" if hint is tuple else hint.__name__
    raise UserError(f"{where}: key {key!r}: expected {tname}, got {type(value).__name__} {_short(value)}")
  if hint is float and not math.isfinite(value):
    raise UserError(f"{where}: key {key!r}: {value!r} is not a finite number")
  items = value if isinstance(value, tuple) else (value,)  # a list (a tuple by now): each element
  choices = field_choices(meta)
  for item in items:
    if choices and item not in choices:
      raise UserError(
        f"{where}: key {key!r}: {item!r} is not one of {', '.join(map(repr, choices))}"
        + suggest(str(item), [str(c) for c in choices])
      )
  if meta.get("minimum") is not None and value < meta["minimum"]:
    raise UserError(f"{where}: key {key!r}: {value!r} is below the minimum {meta['minimum']}")
  if meta.get("below") is not None and not value < meta["below"]:
    raise UserError(f"{where}: key {key!r}: {value!r} must be below {meta['below']}")
  if meta.get("maximum") is not None and value > meta["maximum"]:
    raise UserError(f"{where}: key {key!r}: {value!r} is above the maximum {meta['maximum']}")
  return value
