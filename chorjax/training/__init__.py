"""Training: one run (``driver``: the run directory and the driver that runs a family's step in the ``loop``),
many runs as one program (``vectorized``, ``points``), devices and hosts (``parallel``) and what follows a run
(``end_of_run``). ``train_and_evaluate`` is the package's front door."""

from chorjax.training.driver import train_and_evaluate

__all__ = ["train_and_evaluate"]
