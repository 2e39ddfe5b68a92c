"""Points of a grid (sweep points, ``train.seed=[0,1,2]``) that train together as one vectorized program
(``chorjax.training.vectorized``): which keys may differ between them, and how a command's list overrides expand
into points."""

from __future__ import annotations

import itertools
import json
import math

from chorjax.config import Config, parse_override
from chorjax.errors import UserError
from chorjax.families import family_of

VECTOR_KEYS = ("train.seed", "optim.lr", "train.input_noise")
_FREE = ("name",)  # keys that change only what a point writes
_FREE_SECTIONS = ("sample.", "log.")


class NotAligned(UserError):
  """The points' latest checkpoints are at different steps: they cannot continue as one program."""


def flat_config(cfg: Config) -> dict:
  """``{"section.key": value}`` of a config."""
  out = {}
  for k, v in cfg.to_dict().items():
    if isinstance(v, dict):
      out.update({f"{k}.{kk}": vv for kk, vv in v.items()})
    else:
      out[k] = v
  return out


def check_group(cfgs) -> list[str]:
  """The vectorizable keys in which ``cfgs`` differ; a UserError names any other key that differs."""
  flats = [flat_config(c) for c in cfgs]
  differ = [k for k in flats[0] if len({json.dumps(f[k], sort_keys=True) for f in flats}) > 1]
  for key in differ:
    if key in VECTOR_KEYS or key in _FREE or key.startswith(_FREE_SECTIONS):
      continue
    what = "changes the model's shapes" if key.startswith("model.") else "changes the program or the data"
    a, b = (f[key] for f in flats[:2]) if flats[0][key] != flats[1][key] else (flats[0][key], flats[-1][key])
    raise UserError(
      f"cannot vectorize {key} ({a!r} vs {b!r}): it {what}; only {', '.join(VECTOR_KEYS)} "
      "can differ between points trained together (train the others apart)"
    )
  if cfgs[0].optim.lr <= 0 and "optim.lr" in differ:
    raise UserError("optim.lr: vectorized learning rates need a positive first rate")
  if cfgs[0].train.feedback != "none" and "train.input_noise" in differ:
    raise UserError("train.input_noise cannot differ between vectorized points with train.feedback")
  if cfgs[0].parallel.distributed:
    raise UserError("vectorized training runs in one process (parallel.distributed = false)")
  if family_of(cfgs[0]).vector_step() is None:
    name = cfgs[0].model.family
    raise NotAligned(f"model.family = {name!r}: vectorized training covers the rnn family; train these points apart")
  return [k for k in differ if k in VECTOR_KEYS]


MAX_POINTS = 1024  # models one vectorized program trains together; split a larger grid into a sweep's shards


def expand_overrides(overrides) -> tuple[list[str], list[list[tuple[str, object]]]]:
  """``train.seed=[0,1,2]`` (a list for a vectorizable key) -> the plain overrides and the points:
  one ``[(key, value), ...]`` per combination (a single point, ``[[]]``, when no list is given)."""
  plain, lists = [], []
  for text in overrides:
    key, value = parse_override(text)
    if isinstance(value, list) and key in VECTOR_KEYS:
      if not value:
        raise UserError(f"{key}: an empty list of values")
      lists.append([(key, v) for v in value])
    else:
      plain.append(text)
  count = math.prod(len(values) for values in lists)
  if count > MAX_POINTS:
    raise UserError(
      f"{', '.join(k for k, _ in (v[0] for v in lists))}: {count:,} points; at most {MAX_POINTS:,} train as one program"
    )
  return plain, [list(p) for p in itertools.product(*lists)] if lists else [[]]
