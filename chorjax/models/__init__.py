"""Models: recurrent cells, the stacked core with motion-id conditioning, and MSE/MDN heads."""

from chorjax.models.conditioning import as_weights, motion_weight_vector, parse_mix
from chorjax.models.model import ChorModel, create_model

__all__ = ["ChorModel", "as_weights", "create_model", "motion_weight_vector", "parse_mix"]
