"""chorjax: learn a dancer's movement language from motion capture and write new dance in it.

The data flows one way through the package:
file -> ``data.Motion`` -> pure ``data.transforms`` -> ``data.dataset`` batches -> ``models`` ->
``train`` -> ``checkpoint`` -> ``sample`` -> inverse transforms -> export / ``render``.
"""

__version__ = "0.1.0"
