"""Models: recurrent cells, the stacked core with motion-id conditioning, and MSE/MDN heads."""

from chorjax.models.model import ChorModel, create_model, motion_weights

__all__ = ["ChorModel", "create_model", "motion_weights"]
