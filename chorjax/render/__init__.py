"""Looking at motion: trajectory plots, GIF/MP4 stick figures, and a self-contained HTML player."""
