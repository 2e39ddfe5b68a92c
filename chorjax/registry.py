"""The family registry: how a model family is picked by name (``model.family``).

Training, run loading, sampling, evaluation, calibration, live mode and sweeps ask the family of a config
(:func:`family_of`) and know none by name. The built-in families are imported on first use from
:data:`BUILTIN`; another one is a ``families.family.Family`` subclass handed to :func:`register`. This module
imports nothing of chorjax, so the config schema can ask it which names are valid.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # (for the annotations only: the Family class stands above the config it reads)
  from chorjax.families.family import Family

# name -> the module that registers it when imported (one line per built-in family)
BUILTIN = {
  "rnn": "chorjax.families.recurrent",
  "gan": "chorjax.families.gan",
  "inbetween": "chorjax.families.inbetween",
  "patch": "chorjax.families.patch",
}

_REGISTERED: dict[str, Family] = {}


def register(family: Family) -> Family:
  """Makes ``family`` the one ``model.family = family.name`` picks; returns it."""
  if not family.name:
    raise ValueError("a family needs a name")
  _REGISTERED[family.name] = family
  return family


def names(registered: bool = True) -> tuple[str, ...]:
  """Every family name a config may give: the built-in ones and (``registered``) those registered since."""
  return tuple(dict.fromkeys((*BUILTIN, *(_REGISTERED if registered else ()))))


def sections(registered: bool = True) -> dict[str, type]:
  """The families' own config sections, ``{section: its dataclass}`` (each ``Family.section``), in family order."""
  found = (get(name).section for name in names(registered))
  return dict(section for section in found if section)


def get(name: str) -> Family:
  """The family called ``name`` (KeyError for none)."""
  if name not in _REGISTERED and name in BUILTIN:
    importlib.import_module(BUILTIN[name])
  return _REGISTERED[name]


def family_of(cfg) -> Family:
  """The family of a config (``cfg.model.family``), or of a saved config's dict (``config.json``)."""
  if isinstance(cfg, dict):
    return get(cfg["model"].get("family") or next(iter(BUILTIN)))  # configs older than families: the first
  return get(cfg.model.family)
