"""Models' building blocks that families share: recurrent cells, the stacked core with motion-id
conditioning, and MSE/MDN heads."""

from chorjax.models.conditioning import as_weights, motion_weight_vector, parse_mix

__all__ = ["as_weights", "motion_weight_vector", "parse_mix"]
