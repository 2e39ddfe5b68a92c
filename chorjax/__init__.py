"""chorjax: learn a dancer's movement language from motion capture and write new dance in it.

From Python (the command line is a thin layer over the same functions; see ``chorjax.api``)::

    import chorjax
    run = chorjax.train("configs/quickstart.toml")      # or chorjax.load_run("runs/quickstart")
    dance = run.sample(frames=600, seed=0)               # a Motion: the draw `chorjax sample` makes
    dance.show()                                         # the HTML player, inline in Jupyter
    chorjax.score(dance, "cmu94")                        # the keys of `chorjax metrics`
    dance.write("dance.bvh")

Public names: ``train``, ``load_run`` (a ``Run`` with ``.sample``), ``read_motion``, ``load_dataset``,
``score``, ``Motion`` (``.write``, ``.show``, ``.strip``), ``Player`` and ``UserError`` (every bad input:
the command line's one-line message).

The data flows one way through the package:
file -> ``data.Motion`` -> pure ``data.transforms`` -> ``data.dataset`` batches -> ``models`` ->
``train`` -> ``checkpoint`` -> ``sample`` -> inverse transforms -> export / ``render``.
"""

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # for type checkers and editors; at run time the names load on first use (below)
  from chorjax.api import Motion, Player, Run, UserError, load_dataset, load_run, read_motion, score, train

__version__ = "0.1.0"

_API = ("Motion", "Player", "Run", "UserError", "load_dataset", "load_run", "read_motion", "score", "train")
__all__ = [  # noqa: RUF022  (the API, then the version)
  "Motion",
  "Player",
  "Run",
  "UserError",
  "load_dataset",
  "load_run",
  "read_motion",
  "score",
  "train",
  "__version__",
]


def __getattr__(name: str):
  """The public API, imported on first use (``import chorjax`` stays light for the command line)."""
  if name in _API:
    from chorjax import api  # on first use: importing the package root loads none of it

    return getattr(api, name)
  raise AttributeError(f"module 'chorjax' has no attribute {name!r}")


def __dir__() -> list[str]:
  return sorted([*globals(), *_API])
