"""A config key's declaration: a dataclass field whose metadata holds its help and checks (what
``chorjax config keys``, the flags that set it and the docs' reference show)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any


def config_field(
  default,
  help: str,
  choices: Sequence | Callable[[], Sequence] | None = None,
  minimum: float | None = None,
  resumable: bool = False,
  below: float | None = None,
  more: str | None = None,
  **extra,
) -> Any:
  """A config field: its default, help text (one or two lines: ``chorjax config keys`` and the flags that set
  it show it) and checks; ``more``: what the docs' reference says besides (the reasoning, the measurements).
  ``choices`` of a list field apply to each of its elements; ``resumable`` keys may change when a run is
  continued without --force (e.g. to train longer); ``below``: an exclusive upper bound; ``extra``: more
  metadata (a sampling control's record)."""
  meta = {
    "help": help,
    "more": more,
    "choices": choices if callable(choices) else tuple(choices) if choices else None,
    "minimum": minimum,
    "below": below,
    "resumable": resumable,
    **extra,
  }
  if isinstance(default, (list, tuple)):
    return dataclasses.field(default_factory=lambda: tuple(default), metadata=meta)
  return dataclasses.field(default=default, metadata=meta)
