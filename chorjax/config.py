"""Run configuration: TOML files -> frozen dataclasses; the schema below IS the documentation.

An unknown key, a wrong type or a value outside its allowed set is a ``UserError`` naming the file,
the line and the key, and suggesting the closest valid key. Dotted overrides such as
``model.cell=gru`` are parsed as TOML values (falling back to a bare string) and checked the same way.
"""

from __future__ import annotations

import dataclasses
import json
import re
import tomllib
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from chorjax.errors import UserError, check_draw, check_memory, load_toml, read_text
from chorjax.fields import check_value, field_choices, suggest
from chorjax.registry import family_of
from chorjax.registry import sections as family_sections
from chorjax.sections import (
  DataConfig,
  LogConfig,
  ModelConfig,
  OptimConfig,
  ParallelConfig,
  SampleConfig,
  TrainConfig,
)

_BASE_SECTIONS = {
  "data": DataConfig,
  "model": ModelConfig,
  "optim": OptimConfig,
  "train": TrainConfig,
  "sample": SampleConfig,
  "log": LogConfig,
  "parallel": ParallelConfig,
}


def section_classes() -> dict[str, type]:
  """Every section's dataclass in schema order: the model families' own sections (``[FAMILY]``: each
  family's ``section``) right after ``[model]``."""
  base = list(_BASE_SECTIONS.items())
  return dict([*base[:2], *family_sections().items(), *base[2:]])


@dataclasses.dataclass(frozen=True)
class Config:
  """A run's configuration: a section per attribute (``cfg.train.batch_size``); a model family's own section
  (``cfg.FAMILY``) is read the same way, from ``families`` (each family's defaults where not given)."""

  data: DataConfig = dataclasses.field(default_factory=DataConfig)
  model: ModelConfig = dataclasses.field(default_factory=ModelConfig)
  optim: OptimConfig = dataclasses.field(default_factory=OptimConfig)
  train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
  sample: SampleConfig = dataclasses.field(default_factory=SampleConfig)
  log: LogConfig = dataclasses.field(default_factory=LogConfig)
  parallel: ParallelConfig = dataclasses.field(default_factory=ParallelConfig)
  name: str = "default"
  families: tuple = ()  # ((section, its dataclass instance), ...) of the model families' sections

  def __getattr__(self, name: str) -> Any:  # only for names that are no field: a family's section
    given = dict(self.__dict__.get("families", ()))
    if name in given:
      return given[name]
    cls = None if name.startswith("__") else family_sections().get(name)
    if cls is None:
      raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
    return cls()

  def to_dict(self) -> dict:
    d = {s: dataclasses.asdict(getattr(self, s)) for s in section_classes()} | {"name": self.name}
    return json.loads(json.dumps(d))  # tuples -> lists, a plain JSON tree

  def model_sections(self) -> tuple:
    """The sections that shape a model and its parameters (a checkpoint restored under others is checked
    leaf by leaf): ``[model]`` and the families' own."""
    return (self.model, *(getattr(self, s) for s in family_sections()))


def _config(sections: dict[str, dict], name: str) -> Config:
  """A Config of checked ``{section: {key: value}}`` (what a file or a saved dict gave)."""
  families = tuple((s, cls(**sections[s])) for s, cls in family_sections().items())
  return Config(**{s: cls(**sections[s]) for s, cls in _BASE_SECTIONS.items()}, name=name, families=families)


def key_docs(prefix: str = "", registered: bool = True) -> list[dict]:
  """Every config key under ``prefix`` (a section, ``sample``, or a key, ``sample.pace``), in schema order:
  ``{key, default, help, more, choices, minimum, below}``. A prefix that names nothing is a UserError."""
  rows = []
  for section, cls in section_classes().items():
    defaults = cls()
    for f in dataclasses.fields(cls):
      key = f"{section}.{f.name}"
      if key == prefix or key.startswith(prefix.rstrip(".") + ".") or not prefix:
        meta = f.metadata
        rows.append(
          {
            "key": key,
            "default": getattr(defaults, f.name),
            "help": meta["help"],
            "more": meta.get("more"),
            "choices": field_choices(meta, registered),
            "minimum": meta.get("minimum"),
            "below": meta.get("below"),
            "maximum": meta.get("maximum"),
          }
        )
  if not rows:
    raise UserError(f"{prefix!r}: no such config key or section" + suggest(prefix, [*section_classes(), *valid_keys()]))
  return rows


def reference_markdown() -> str:
  """Every config key as the docs' reference page (``docs/config.md``): a table a section, each key's
  default, help with its range, and the notes of ``more``."""
  lines = ["# Config reference", "", "Generated from the config fields (`chorjax config keys --markdown`).", ""]
  section = None
  for row in key_docs(registered=False):  # the families chorjax ships, whatever this process registered
    name = row["key"].split(".")[0]
    if name != section:
      lines += [""] if section else []
      section = name
      lines += [f"## [{name}]", "", "| key | default | what it does |", "| --- | --- | --- |"]
    text = key_help(row) + (f"<br>*More:* {row['more']}" if row["more"] else "")
    cells = (f"`{row['key']}`", f"`{toml_value(row['default'])}`", text)
    lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
  return "\n".join(lines) + "\n"


def key_help(key: str | dict) -> str:
  """The help of one config key (or of a row of :func:`key_docs`), with its range or choices (what a flag
  that sets it says)."""
  row = key_docs(key)[0] if isinstance(key, str) else key
  bounds = []
  if row["choices"]:
    bounds.append("one of " + ", ".join(map(str, row["choices"])))
  if row["minimum"] is not None:
    bounds.append(f">= {row['minimum']:g}")
  if row["below"] is not None:
    bounds.append(f"< {row['below']:g}")
  if row["maximum"] is not None:
    bounds.append(f"<= {row['maximum']:g}")
  return row["help"] + (f" [{', '.join(bounds)}]" if bounds else "")


def valid_keys() -> list[str]:
  return [f"{s}.{f.name}" for s, cls in section_classes().items() for f in dataclasses.fields(cls)]


def resumable_keys() -> list[str]:
  """Dotted keys that may change when a run is continued without --force (a field flag in the schema)."""
  return [
    f"{s}.{f.name}" for s, cls in section_classes().items() for f in dataclasses.fields(cls) if f.metadata["resumable"]
  ]


def _check_value(where: str, key: str, field: dataclasses.Field, value: Any):
  """Returns ``value`` converted to the field's type, or raises a UserError naming ``key``."""
  hint = typing.get_type_hints(section_classes()[key.split(".")[0]])[field.name]
  return check_value(where, key, field, hint, value)


def _line_of(text: str, section: str, key: str) -> int | None:
  """The line of ``key`` inside ``[section]`` (tomllib does not report positions)."""
  current = None
  for i, line in enumerate(text.splitlines(), start=1):
    m = re.match(r"\s*\[([^\]]+)\]\s*(#.*)?$", line)
    if m:
      current = m.group(1).strip()
      continue
    if re.match(rf"\s*{re.escape(key)}\s*=", line) and current == section:
      return i
    if re.match(rf"\s*{re.escape(section)}\.{re.escape(key)}\s*=", line) and current is None:
      return i
  return None


def _apply(sections: dict[str, dict], tree: dict, where_of) -> None:
  """Checks a ``{section: {key: value}}`` tree and merges it into ``sections``."""
  for section, body in tree.items():
    if section == "name":
      continue
    if section not in section_classes():
      raise UserError(
        f"{where_of(section, None)}: unknown section {section!r}" + suggest(section, list(section_classes()))
      )
    if not isinstance(body, dict):
      raise UserError(f"{where_of(section, None)}: {section!r} must be a table ([{section}])")
    fields = {f.name: f for f in dataclasses.fields(section_classes()[section])}
    for key, value in body.items():
      dotted = f"{section}.{key}"
      if key not in fields:
        raise UserError(f"{where_of(section, key)}: unknown key {dotted!r}" + suggest(dotted, valid_keys()))
      sections[section][key] = _check_value(where_of(section, key), dotted, fields[key], value)


def parse_override(text: str) -> tuple[str, Any]:
  """``'optim.lr=3e-4'`` -> ``('optim.lr', 0.0003)``; values are TOML, else bare strings."""
  if "=" not in text:
    raise UserError(f"override {text[:80]!r}: expected KEY=VALUE, e.g. model.cell=gru")
  key, raw = (s.strip() for s in text.split("=", 1))
  try:
    value = load_toml(f"v = {raw}")["v"]
  except tomllib.TOMLDecodeError:
    value = raw
  return key, value


MAX_BASES = 16  # configs a file may stand on, one on another (base = "...")


def _apply_file(sections: dict[str, dict], path: Path, below: tuple = ()) -> str:
  """Merges the config file ``path`` into ``sections``: first the file its top-level ``base = "FILE"`` names
  (a path relative to it; that file's own base first, and so on), then its own keys. Returns its name (its
  ``name``, else its file name's stem)."""
  try:
    text = read_text(path, "config")  # a byte-order mark some editors write is not TOML; pipes refused
  except OSError as e:
    raise UserError(f"{path}: cannot read ({type(e).__name__})") from None
  try:
    tree = load_toml(text)
  except tomllib.TOMLDecodeError as e:
    raise UserError(f"{path}: invalid TOML: {e}") from None

  def where_of(section, key):
    line = _line_of(text, section, key) if key else _line_of_section(text, section)
    return f"{path}:{line}" if line else str(path)

  base = tree.pop("base", None)
  if base is not None:
    where = f"{path}:{_line_of_section(text, 'base') or 1}"
    if not isinstance(base, str) or not base:
      raise UserError(f"{where}: key 'base': expected the path of another config file")
    below = (*below, path.resolve())
    target = path.parent / base
    if target.resolve() in below or len(below) > MAX_BASES:
      raise UserError(f"{where}: base {base!r} leads back to itself ({' -> '.join(p.name for p in below)})")
    if not target.is_file():
      raise UserError(f"{where}: base {base!r}: no such file beside it ({target})")
    _apply_file(sections, target, below)
  _apply(sections, tree, where_of)
  name = tree.get("name", path.stem)
  if not isinstance(name, str):
    raise UserError(f"{path}: key 'name': expected str")
  return name


def load_config(path: str | Path | Config | dict | None = None, overrides: Sequence[str] = ()) -> Config:
  """Loads a TOML config file (or the defaults, a loaded ``Config``, or a ``{section: {key: value}}`` dict as
  a file's tables would be) and applies dotted ``KEY=VALUE`` overrides.

  Raises:
    UserError: for a missing or malformed file, an unknown section or key, a wrong type, or a
      value out of range; the message names the file (and line) or the override.
  """
  sections: dict[str, dict] = {s: {} for s in section_classes()}
  name = "default"
  if isinstance(path, Config):  # chorjax.train(config) from Python: the same overrides, the same checks
    _apply(sections, {k: v for k, v in path.to_dict().items() if k != "name"}, lambda s, k: "the given config")
    name = path.name
  elif isinstance(path, dict):  # chorjax.train({"model": {"cell": "gru"}}): checked as a file's tables are
    _apply(sections, path, lambda s, k: "the given dict")
    name = str(path.get("name", name))
  elif isinstance(path, str | Path):
    name = _apply_file(sections, Path(path))
  elif path is not None:
    raise UserError(f"config: expected a TOML file's path, a Config or a dict, got {type(path).__name__}")
  for item in overrides:
    key, value = parse_override(item)
    if key == "name":
      name = str(value)
      continue
    if "." not in key:
      raise UserError(f"override {item[:80]!r}: expected SECTION.KEY=VALUE" + suggest(key, valid_keys()))
    section, sub = key.split(".", 1)
    _apply(sections, {section: {sub: value}}, lambda s, k, item=item: f"override {item[:80]!r}")
  config = _config(sections, plain_name(name, "name"))
  check_combinations(config)
  check_training_size(config)
  return config


def check_combinations(config: Config) -> None:
  """Keys that make sense alone but not together, refused when a config is loaded (before any training;
  runs already saved with them still load: their sampling says so when asked)."""
  if not config.data.cache.strip():  # an empty path is the working directory: entries among the user's files
    raise UserError("key 'data.cache': empty; give auto, off, or a folder")
  parts, size = config.train.batch_parts, config.train.batch_size
  if parts > 1 and size % parts:
    raise UserError(f"key 'train.batch_parts': {parts} does not divide train.batch_size = {size}")
  family_of(config).check_keys(config)  # keys of another model family's
  if parts > 1 and config.parallel.data_parallel:
    raise UserError(
      "key 'train.batch_parts': not with parallel.data_parallel (the batch is shared over the devices already)"
    )
  rep = config.data.representation
  for key in ("foot_lock", "ground"):
    if getattr(config.sample, key) and rep != "canonical":
      raise UserError(
        f"key 'sample.{key}': needs data.representation = 'canonical' (here {rep!r}); set sample.{key}=false"
      )


FEATURES_GUESS = 256  # pose features per frame, more than any skeleton we read gives (mpii16 canonical: ~50)


def training_bytes(config: Config) -> float:
  """What one model's train step needs, estimated from the sizes alone (:func:`check_training_size`): the
  parameters with Adam's two moments, and the activations the step keeps for its backward pass, in float32."""
  m, t, d = config.model, config.train, config.data
  h, layers, inputs = m.hidden_size, m.num_layers, FEATURES_GUESS
  params = layers * 4 * h * (h + max(h, inputs)) + h * FEATURES_GUESS * (2 * m.num_mixtures + 1)
  components = m.num_mixtures if m.head == "mdn" else 1
  activations = t.batch_size * d.seq_length * (layers * h * 16 + components * FEATURES_GUESS * 6)
  return 4.0 * (3 * params + activations)


def check_training_size(config: Config, copies: int = 1) -> None:
  """A one-line ``UserError`` naming the keys when training would need more memory than this machine has,
  estimated from the sizes alone (before anything is allocated): the parameters with Adam's two moments,
  and the activations a step keeps for its backward pass (about 16 values per unit, layer and frame, and the
  head's: about 6 per feature and mixture component per frame, which rule small models); for ``copies``
  models trained together as one program (a list of seeds), all of them."""
  m, t, d = config.model, config.train, config.data
  together = f" x {copies:,} points trained together" if copies > 1 else ""
  check_memory(
    training_bytes(config) * copies,
    f"model.hidden_size={m.hidden_size}, model.num_layers={m.num_layers}, train.batch_size={t.batch_size}, "
    f"data.seq_length={d.seq_length}{together}",
  )
  # the sample written at the end of training (as Run.check_drawn counts a draw), before training starts
  check_draw(config.sample.frames * copies, FEATURES_GUESS // 4 + 48, f"sample.frames={config.sample.frames}")


def plain_name(name: str, what: str) -> str:
  """``name`` if it can be one folder's name (runs/<name>), else a one-line UserError: a name with ``/`` or
  ``..`` would write a run outside the runs folder."""
  if not name or name.startswith(".") or ".." in name or any(c in name for c in "/\\\0") or len(name) > 200:
    raise UserError(f"{what} {name!r}: must be a plain file name (no / or \\, no .., not starting with .)")
  return name


def _line_of_section(text: str, section: str) -> int | None:
  for i, line in enumerate(text.splitlines(), start=1):
    if re.match(rf"\s*\[{re.escape(section)}\]", line) or re.match(rf"\s*{re.escape(section)}\s*=", line):
      return i
  return None


def config_from_dict(d: dict) -> Config:
  """Rebuilds a Config saved with ``to_dict`` (checked like a file)."""
  sections: dict[str, dict] = {s: {} for s in section_classes()}
  _apply(sections, {k: v for k, v in d.items() if k != "name"}, lambda s, k: "saved config")
  return _config(sections, d.get("name", "default"))


def config_diff(a: Config, b: Config, ignore: Sequence[str] = ()) -> list[str]:
  """Dotted keys whose values differ between two configs."""
  da, db = a.to_dict(), b.to_dict()
  out = []
  for s in section_classes():
    for k in da[s]:
      if da[s][k] != db[s][k] and f"{s}.{k}" not in ignore:
        out.append(f"{s}.{k}: {da[s][k]!r} -> {db[s][k]!r}")
  return out


def toml_value(v) -> str:
  """A config value as TOML writes it."""
  if isinstance(v, bool):
    return "true" if v else "false"
  if isinstance(v, str):
    return json.dumps(v)
  if isinstance(v, (list, tuple)):
    return "[" + ", ".join(toml_value(x) for x in v) + "]"
  return repr(v)


def to_toml(cfg: Config) -> str:
  """The resolved config as TOML text (what ``chorjax config show`` prints)."""
  fmt = toml_value
  lines = [f"name = {fmt(cfg.name)}"]
  for s, body in cfg.to_dict().items():
    if s == "name":
      continue
    lines.append(f"\n[{s}]")
    lines += [f"{k} = {fmt(v)}" for k, v in body.items()]
  return "\n".join(lines) + "\n"
