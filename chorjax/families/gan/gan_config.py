"""The ``[gan]`` keys: the LSTM-GAN family's settings, registered with the family (``Family.section``)."""

from __future__ import annotations

import dataclasses

from chorjax.fields import config_field as _field


@dataclasses.dataclass(frozen=True)
class GanConfig:
  """The LSTM-GAN family (``model.family = "gan"``); the optimizer is ``[optim]``'s, with these learning rates."""

  latent_size: int = _field(64, "size of the noise vector the generator turns into a sequence", minimum=1)
  generator_dense: tuple = _field((128,), "the generator's dense ReLU layers between the noise and its LSTM")
  frame_noise: int = _field(
    0,
    "channels of fresh noise fed to the generator's LSTM at every frame (0 = one repeated noise vector)",
    more=("0 is the tutorial's generator; an LSTM driven by a constant input tends to settle into one still pose."),
    minimum=0,
  )
  generator_layers: int = _field(2, "the generator's stacked recurrent layers", minimum=1)
  generator_size: int = _field(512, "units per generator recurrent layer", minimum=1)
  critic_layers: int = _field(2, "the critic's stacked recurrent layers", minimum=1)
  critic_size: int = _field(512, "units per critic recurrent layer", minimum=1)
  critic_dense: tuple = _field((512,), "the critic's dense ReLU layers after its last time step")
  cell: str = _field("lstm", "recurrent cell of generator and critic", choices=("lstm", "lnlstm", "gru"))
  loss: str = _field(
    "bce",
    "adversarial loss: 'bce' (binary cross-entropy) or 'wgan-gp' (Wasserstein critic with gradient penalty)",
    more=("bce is the tutorial's loss with a non-saturating generator; wgan-gp is the stable alternative."),
    choices=("bce", "wgan-gp"),
  )
  gp_weight: float = _field(10.0, "weight of the gradient penalty (wgan-gp)", minimum=0.0)
  critic_steps: int = _field(1, "critic updates per generator update, each on its own real batch", minimum=1)
  generator_lr: float = _field(1e-4, "generator learning rate (peak, under optim.schedule)", minimum=0.0)
  critic_lr: float = _field(1e-4, "critic learning rate (peak, under optim.schedule)", minimum=0.0)
  pose: str = _field(
    "directions",
    "what the generator writes: bone 'directions', joint 'rotations' (quaternions, forward kinematics) or 'features'",
    more=(
      "directions and rotations need data.representation = directions (bones keep the takes' mean lengths). "
      "Rotations go through forward kinematics from the takes' mean rest directions; they are the "
      "generator's own, not a file's channels."
    ),
    choices=("directions", "rotations", "features"),
  )
