"""The sampling controls, each declared once.

:class:`ControlFields` is the table: one field per control, its default, help and checks as a ``[sample]``
key, and a :class:`Control` record of what the draw does with it. Everything that names the controls is made
from it: the ``[sample]`` keys (``sections.SampleConfig`` inherits the fields), the flags of ``sample``,
``eval``, ``export`` and ``live`` (``cli``), the controls a draw resolves (``controls.Controls``), the model's
own draw (:data:`PLAIN`), what calibration searches (:data:`GRID`, :data:`CARRIED_GRID`, the ladders past
their ends) and what ``calibration.json`` may hold (:data:`CALIBRATED`). A control is a *draw* control (how
each frame is drawn) or a *decoding* one (how drawn features become joints: rigid bones, grounded and locked
feet), which the draw's count leaves out.
"""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

from chorjax.fields import check_value, config_field

# The most AR(1) filters the MDN noise can pass (``sample.noise_order``): a stream's state holds this many, so
# the order may change between chunks of an endless dance.
MAX_NOISE_ORDER = 8
_RUN = object()  # a decoding control's value under ``--plain``: the run's own


@dataclasses.dataclass(frozen=True)
class Control:
  """What the draw does with a control.

  Attributes:
    role: "draw" (how a frame is drawn) or "decoding" (how drawn features become joints).
    flag: a flag of its own on ``sample``, ``eval``, ``export`` and ``live`` (the three draw controls of the
      default draw, and decoding's); the others are opt-ins, set as ``--set sample.KEY=VALUE``.
    metavar: the flag's metavar for a number (``--pace GAIN``); None for an on/off switch.
    plain: the value in the model's own draw (``--plain``); decoding keeps the run's.
    grid: the values calibration tries for a white-noise MDN (empty: not searched).
    carried_grid: ... for an MDN that carries its noise over frames (``model.mdn_memory``).
    beyond: (lower, higher) ladders calibration walks past the grid's ends while its objective falls.
    carried_beyond: the same past ``carried_grid``'s ends.
    recorded: not searched, but saved with the chosen settings (they were chosen under its value).
    traced: a traced leaf of ``controls.Controls`` (one compiled program for every value); else static.
    head: the MDN head's draw takes it (``heads.MDNHead.draw``); the others act around the head.
  """

  role: str = "draw"
  flag: bool = False
  metavar: str | None = None
  plain: Any = _RUN
  grid: tuple = ()
  carried_grid: tuple = ()
  beyond: tuple = ()
  carried_beyond: tuple = ()
  recorded: bool = False
  traced: bool = False
  head: bool = False


def control(default, help: str, record: Control, **key) -> Any:
  """A control's field: its ``[sample]`` key (``fields.config_field``'s ``key`` arguments) and its ``record``."""
  return config_field(default, help, control=record, **key)


@dataclasses.dataclass(frozen=True)
class ControlFields:
  """The sampling controls, in ``[sample]``'s order (``chorjax config keys sample`` says what each does)."""

  pi_temperature: float = control(
    1.0,
    "MDN mixture-weight temperature (0 = most likely component)",
    Control(metavar="T", plain=1.0, traced=True, head=True),
    minimum=0.0,
    below=1000.0,
  )
  sigma_temperature: float = control(
    1.0,
    "MDN scale multiplier",
    # An MDN that carries its noise draws smoothly at full temperature: what is left to choose is how wide its
    # draws are (on the dancers benchmark's runs, its own draw on martial's training takes moved at 1.5-1.6x
    # their speed at temperature 1 and 0.93x at 0.5), walking below to where a dancer with half a minute of
    # motion is drawn (CMU 5's three runs chose 0.5 with nothing lower to try; one walking down chose 0.3:
    # held-out jitter 1.35 -> 0.88, FID_g 2.7 -> 1.8x). The white grid's ends bound 29 of the 39 chosen
    # temperatures of the benchmark's runs (0.9: 24, most on cmu94 and salsa; 1.2: 5).
    Control(
      flag=True,
      metavar="S",
      plain=1.0,
      grid=(0.9, 1.0, 1.2),
      carried_grid=(0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1, 1.2),
      beyond=((0.8, 0.7, 0.6, 0.5), (1.4, 1.7, 2.0)),
      carried_beyond=((0.4, 0.3, 0.25, 0.2), (1.4, 1.7, 2.0)),
      traced=True,
      head=True,
    ),
    minimum=0.0,
    below=1000.0,
  )
  greedy: bool = control(False, "take the mean of the most likely component (no noise)", Control(plain=False))
  noise_smoothing: float = control(
    0.0,
    "MDN noise correlated over frames: the coefficient of the noise_order AR(1) filters it passes (0 = white noise)",
    # 0.95: a model that trembles (cmu05 seed 1: jitter 3 at 0.9)
    Control(metavar="RHO", plain=0.0, grid=(0.6, 0.75, 0.85, 0.9, 0.95), beyond=((0.5, 0.4, 0.3), (0.97, 0.98))),
    more="The filters keep unit variance, so a full-temperature sample moves smoothly instead of trembling.",
    minimum=0.0,
    below=1.0,
    resumable=True,
  )
  noise_order: int = control(
    2,
    "how many AR(1) filters, each with coefficient noise_smoothing, the MDN noise passes",
    Control(metavar="N", plain=1, recorded=True),
    more=(
      "Two filters leave a tremble in every frame's change; four at 0.8 move as fast per frame as two at "
      "0.9 with a third of the second difference."
    ),
    minimum=1,
    below=MAX_NOISE_ORDER + 1,
    resumable=True,
  )
  # Persistence is not walked past its grid (6 already holds a component until another outweighs it: 12 draws
  # the same).
  persistence: float = control(
    0.0,
    "bonus to the log-weight of the previous frame's mixture component (0 = off)",
    Control(metavar="P", plain=0.0, grid=(0.0, 1.5, 6.0), traced=True, head=True),
    more="The dancer does not hop between mixture components every frame.",
    minimum=0.0,
    resumable=True,
  )
  crossfade: float = control(
    0.0,
    "MDN component switches glide: the jump between the means decays by this factor per frame (0 = off)",
    Control(metavar="F", plain=0.0, grid=(0.0, 0.8), traced=True, head=True),
    more="At 0.8 a switch's jump is mostly gone after 10 frames.",
    minimum=0.0,
    below=1.0,
    resumable=True,
  )
  pace: float = control(
    0.0,
    "pace governor gain g: scale temperature x m = (training / own pace)^g in 0.5-2, persistence x min(m, 1/m)^2",
    Control(flag=True, metavar="GAIN", plain=0.0, recorded=True),
    more=(
      "The pace is how far the joints move relative to the root in half a second, turning included (the "
      "pose features where the run has no canonical features), averaged over about 5 s: a dancer who slows "
      "gets more energy, one who races less, and either lets go of its component sooner. A run conditioned on "
      "labels (data.labels) holds each dancer to the pace of its own labels' training takes."
    ),
    minimum=0.0,
    below=100.0,  # past it the governor is on or off: the multiplier at its bounds for any difference in pace
    resumable=True,
  )
  scale_cap: float = control(
    0.0,
    "hold MDN scales at most at this quantile of the model's own scales on its training frames (0 = off)",
    Control(metavar="Q", plain=0.0, head=True),
    more=(
      "Teacher forced on the training frames, e.g. 0.95: a model unsure of a state then draws a calm frame "
      "and finds its way back. Needs the run's training data at sampling time."
    ),
    minimum=0.0,
    below=1.0,
    resumable=True,
  )
  rigid_bones: bool = control(
    False,
    "decode with the training takes' mean bone lengths: bones cannot stretch",
    Control(role="decoding", flag=True),
    more="Each bone keeps its direction.",
    resumable=True,
  )
  foot_lock: bool = control(
    False,
    "canonical runs: a foot in contact with the floor does not slide",
    Control(role="decoding", flag=True, grid=(True, False), carried_grid=(True, False)),  # canonical runs only
    more=(
      "The body travels by what its legs do: the slide of the feet in contact, averaged over 17 frames, is taken "
      "back, so a slide that lasts is gone while a foot's tremble does not shake the whole body."
    ),
    resumable=True,
  )
  ground: bool = control(
    False,
    "canonical runs: feet in contact with the floor stand on the training floor, no floating",
    Control(role="decoding", flag=True),
    more=(
      "The body is moved up or down to the floor smoothly (averaged over 17 frames), never faster than the takes' "
      "fastest vertical root step."
    ),
    resumable=True,
  )
  clamp: bool = control(
    False,
    "clip every generated frame to the training features' range before it is fed back",
    Control(flag=True, plain=False),
    more="Feature by feature: the model is never fed a frame unlike its training inputs.",
    resumable=True,
  )
  clamp_steps: bool = control(
    False,
    "clip every frame's change from the previous one to the range of the training frames' changes",
    Control(plain=False),
    more="Feature by feature: a component that flickers for a frame cannot jump further than the data ever does.",
    resumable=True,
  )


def _records() -> dict[str, Control]:
  return {f.name: f.metadata["control"] for f in dataclasses.fields(ControlFields)}


RECORDS = _records()
NAMES = tuple(RECORDS)
SWITCHES = tuple(n for n, c in RECORDS.items() if c.metavar is None)  # the on/off controls
DECODING = tuple(n for n, c in RECORDS.items() if c.role == "decoding")
FLAGGED = tuple(n for n, c in RECORDS.items() if c.flag)  # a flag each; the others: --set sample.KEY=VALUE
DRAW_FLAGS = tuple(n for n in FLAGGED if RECORDS[n].role == "draw")
TRACED = tuple(n for n, c in RECORDS.items() if c.traced)
HEAD = tuple(n for n, c in RECORDS.items() if c.head)
# The model's own draw (``--plain``): full temperature, white noise, nothing held, smoothed, governed or clipped;
# decoding (rigid bones, grounded and locked feet) stays the run's.
PLAIN = {n: c.plain for n, c in RECORDS.items() if c.plain is not _RUN}
GRID = {n: c.grid for n, c in RECORDS.items() if c.grid}
CARRIED_GRID = {n: c.carried_grid for n, c in RECORDS.items() if c.carried_grid}
BEYOND = {n: c.beyond for n, c in RECORDS.items() if c.beyond}
CARRIED_BEYOND = {n: c.carried_beyond for n, c in RECORDS.items() if c.carried_beyond}
RECORDED = tuple(n for n, c in RECORDS.items() if c.recorded)  # not searched: what the settings were chosen with
# What calibration.json's settings may hold: what `chorjax calibrate` chooses, and what it was chosen with (an
# older calibration may hold fewer: noise_smoothing and sigma_temperature alone, or no noise_order or pace, which
# were then the run's sample.noise_order and sample.pace)
CALIBRATED = tuple(n for n, c in RECORDS.items() if c.grid or c.carried_grid or c.recorded)


@dataclasses.dataclass(frozen=True)
class Given:
  """A control's value as the command line gave it, with the flag that gave it (``--pace``, ``--set
  sample.pace``): ``Controls.resolve`` checks it once and names the flag in its error."""

  value: Any
  where: str


def check_sample_control(name: str, value, where: str):
  """``value`` checked as ``[sample] name`` is in a config file (type, range, finite); ``where`` names
  its source in the error (e.g. the command-line flag)."""
  field = {f.name: f for f in dataclasses.fields(ControlFields)}[name]
  return check_value(where, f"sample.{name}", field, typing.get_type_hints(ControlFields)[name], value)
