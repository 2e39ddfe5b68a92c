"""Looking at motion: trajectory plots, GIF/MP4 stick figures, and a self-contained HTML player, each a format
of the registry (``drawers``)."""

from chorjax.render import drawers  # noqa: F401  (registers the pictures: PNG, GIF/MP4, the HTML player)
