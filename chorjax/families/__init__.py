"""Model families, one package each, picked by ``model.family`` through the registry.

* ``recurrent/`` (``rnn``): chor-rnn's recurrent core predicting every next frame through an MDN or MSE head.
* ``gan/`` (``gan``): the LSTM-GAN, a generator of whole sequences from noise and its critic.
* ``inbetween/`` (``inbetween``): transition models (an LSTM and a CVAE) that write the frames between poses.

Nothing outside this package names a family: it asks :func:`family_of` a config's family.
"""

from chorjax.registry import family_of, get, names, register

__all__ = ["family_of", "get", "names", "register"]
