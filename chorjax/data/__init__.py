"""Data side: files -> Motion -> pure transforms -> dataset batches."""

from chorjax.data.motion import Motion, Skeleton

__all__ = ["Motion", "Skeleton"]
