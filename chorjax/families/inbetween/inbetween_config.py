"""The ``[inbetween]`` keys: the in-betweening family's settings, registered with it (``Family.section``)."""

from __future__ import annotations

import dataclasses

from chorjax.fields import config_field as _field


@dataclasses.dataclass(frozen=True)
class InbetweenConfig:
  """The in-betweening family (``model.family = "inbetween"``): a recurrent transition model (Harvey et al.
  2020) that writes what lies between a context phrase and a target pose; see ``chorjax.inbetween``."""

  system: str = _field(
    "lstm",
    "the transition model: 'lstm' (Harvey et al. 2020) or 'cvae' (Tang et al. 2022: a motion manifold and a sampler)",
    more=(
      "lstm writes each frame's deviation from linear interpolation, conditioned on the target pose and the "
      "time to arrival; cvae trains a conditional VAE manifold with a mixture-of-experts decoder first, "
      "then a recurrent sampler of its latents with the decoder frozen."
    ),
    choices=("lstm", "cvae"),
  )
  context: int = _field(10, "frames of the phrase the model sees before a transition", minimum=2)
  min_frames: int = _field(5, "shortest transition trained on (frames between context and target)", minimum=1)
  max_frames: int = _field(30, "longest transition trained on; longer ones are written beyond it", minimum=1)
  encoder_sizes: tuple = _field(
    (256, 256), "ELU layers of each of the three encoders (state, offset to target, target)"
  )
  decoder_sizes: tuple = _field((256,), "ELU layers of the decoder before its output (which starts at zero)")
  target_noise: float = _field(
    0.5,
    "std of the noise on the target (lstm) or of the sampler's latents (cvae): seeds write different transitions",
    more=(
      "lstm: added once per transition to the target and offset encodings, fading over the last 5-30 frames "
      "before arrival (Harvey et al.'s z_target); cvae: latents drawn as mu + target_noise x sigma x eps."
    ),
    minimum=0.0,
  )
  velocity_weight: float = _field(
    1.0, "weight of the L1 loss on frame-to-frame steps beside the pose loss", minimum=0.0
  )
  latent_size: int = _field(32, "cvae: size of the manifold's latent z", minimum=1)
  manifold_encoder_sizes: tuple = _field((256, 256), "cvae: ELU layers of the manifold's encoder")
  experts: int = _field(6, "cvae: expert networks of the manifold's decoder", minimum=1)
  expert_sizes: tuple = _field((256, 256, 256), "cvae: ELU layers of each expert (z and the root's step fed to each)")
  gate_sizes: tuple = _field((256, 256), "cvae: ELU layers of the gating network (then a softmax over the experts)")
  manifold_steps: int = _field(
    2000, "cvae: steps of stage 1 (the manifold); the rest of train.num_steps train the sampler", minimum=1
  )
  manifold_frames: int = _field(8, "cvae: frames each stage-1 window rolls out", minimum=1)
  sampling_ramp: int = _field(
    1000,
    "cvae: stage-1 steps over which scheduled sampling's p (the chance that the previous frame is the model's "
    "own) rises linearly from 0 to 1",
    minimum=1,
  )
  kl_weight: float = _field(
    1e-5,
    "cvae: weight of stage 1's KL term",
    more=(
      "Beside a reconstruction that is a mean L1 per coordinate in leg lengths (about 0.003-0.01); on "
      "cmu94, 0.1 and 5e-4 collapsed the posterior, 1e-5 keeps it some 70 nats."
    ),
    minimum=0.0,
  )
  physics_start: int = _field(
    1000,
    "cvae: the stage-1 step from which the foot-skating and bone-length losses join",
    more=("Their weight ramps from 0 to 1 over the rest of stage 1, while the learning rate is warmed again from 0."),
    minimum=0,
  )
