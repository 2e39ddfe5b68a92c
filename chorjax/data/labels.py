"""Named labels that condition a run in place of per-take ids (``data.labels``): read from the takes' file
names by a pattern with named groups, or from a CSV file with one row per take.

A run of a labelled library (``dataset-2_walk_elderly_003``: action ``walk``, style ``elderly``) then dances
"walk, elderly" on request (``--motion action=walk,style=elderly``), blends values (``--mix
style=elderly:0.5,style=active:0.5``), and a take it never saw is conditioned by its labels.
"""

from __future__ import annotations

import csv
import dataclasses
import io

import numpy as np
import regex

from chorjax.errors import UserError, read_text

MAX_LABEL_CHARS = 10_000  # a --motion or --mix of labels: longer text is refused unread


@dataclasses.dataclass(frozen=True)
class Labels:
  """Named labels that condition a run in place of per-take ids (``data.labels``): one or more fields
  (``action``, ``style``), each with its values; the model reads one weight per value, a take's weights
  being the one-hot of its value in every field (each field its own embedding, summed by the model's
  initial-state layer).

  Attributes:
    fields: field -> its values (sorted), in the order the pattern or the CSV names them.
    pattern: the regular expression read from take names (named groups), or None (a CSV gave them).
    table: take name -> {field: value}: the CSV's rows (empty with a pattern: the names say it).
  """

  fields: dict
  pattern: str | None
  table: dict

  @property
  def names(self) -> list[str]:
    """``field=value`` for every weight, in the model's order."""
    return [f"{f}={v}" for f, values in self.fields.items() for v in values]

  def of_take(self, name: str) -> dict | None:
    """The take's labels: its row, else what the pattern reads from its name (None: neither knows it)."""
    if name in self.table:
      return self.table[name]
    found = search_name(self.pattern, name, "data.labels") if self.pattern else None
    return None if found is None else {f: found.group(f) for f in self.fields}

  def vector(self, labels: dict) -> np.ndarray:
    """The weights ``[M]`` of one value per field (``{field: value}``; a value the run never saw is refused)."""
    return self.weights({f: {v: 1.0} for f, v in labels.items()}, "labels")

  def weights(self, blend: dict, source: str) -> np.ndarray:
    """``{field: {value: weight}}`` -> the weights ``[M]``: each field's weights normalized to sum 1, a field
    not given spread evenly over its values (the dance is then of no one value of it)."""
    for field, given in blend.items():
      if field not in self.fields:
        raise UserError(f"{source}: no label {field!r}; this run's labels: {', '.join(self.fields)}")
      unknown = [v for v in given if v not in self.fields[field]]
      if unknown:
        known = ", ".join(self.fields[field])
        raise UserError(f"{source}: {field}={unknown[0]!r} is not a value this run knows; {field}: {known}")
    out = []
    for field, values in self.fields.items():
      given = blend.get(field, {})
      w = np.array([float(given.get(v, 0.0)) for v in values]) if given else np.ones(len(values))
      out.append(w / w.sum())
    return np.concatenate(out).astype(np.float32)

  def parse(self, motion=None, mix=None, source: str = "--motion") -> np.ndarray:
    """``--motion action=walk,style=elderly`` or ``--mix style=elderly:0.5,style=active:0.5`` -> weights
    ``[M]`` (nothing given: each field's first value)."""
    if mix:
      return self.weights(_label_pairs(mix, "--mix", weighted=True), "--mix")
    if motion is None:
      return self.weights({f: {values[0]: 1.0} for f, values in self.fields.items()}, source)
    if not isinstance(motion, str) or "=" not in motion:
      example = ",".join(f"{f}={values[0]}" for f, values in self.fields.items())
      raise UserError(f"{source} {motion!r}: this run is conditioned on labels, not take ids: e.g. {example}")
    return self.weights(_label_pairs(motion, source, weighted=False), source)

  def to_dict(self) -> dict:
    return {"fields": {f: list(v) for f, v in self.fields.items()}, "pattern": self.pattern, "table": self.table}

  @classmethod
  def from_dict(cls, d: dict) -> Labels:
    return cls({f: tuple(v) for f, v in d["fields"].items()}, d["pattern"], dict(d["table"]))


def _label_pairs(text: str, source: str, weighted: bool) -> dict:
  """``a=x,b=y`` (or ``a=x:0.5,a=z:0.5``) -> ``{field: {value: weight}}``."""
  if len(text) > MAX_LABEL_CHARS:
    raise UserError(f"{source}: {len(text)} characters; at most {MAX_LABEL_CHARS}")
  form = "FIELD=VALUE:WEIGHT,..." if weighted else "FIELD=VALUE,FIELD=VALUE"
  out: dict = {}
  for part in text.split(","):
    label, _, weight = part.rpartition(":") if weighted else (part, "", "1")
    field, eq, value = label.partition("=")
    try:
      w = float(weight)
    except ValueError:
      w = float("nan")
    if not (eq and field.strip() and value.strip()) or not (np.isfinite(w) and w >= 0):
      raise UserError(f"{source} {text[:80]!r}: expected {form} (weights finite and >= 0)")
    if not weighted and field.strip() in out:
      raise UserError(f"{source} {text[:80]!r}: {field.strip()} given twice (a blend is --mix)")
    values = out.setdefault(field.strip(), {})
    values[value.strip()] = values.get(value.strip(), 0.0) + w
  if any(sum(v.values()) <= 0 for v in out.values()):
    raise UserError(f"{source} {text[:80]!r}: each label's weights must sum to a positive number")
  return out


PATTERN_SECONDS = 1.0  # the longest one take's name may take to match a pattern


def search_name(pattern: str, name: str, where: str):
  """``regex.search(pattern, name)``, or a UserError naming ``where`` if it takes over ``PATTERN_SECONDS``: a
  pattern of nested repeats (``(a+)+``) backtracks for ages on a name it nearly matches."""
  try:
    return regex.search(pattern, name, timeout=PATTERN_SECONDS)
  except TimeoutError:
    raise UserError(
      f"{where} = {pattern[:80]!r}: matching take {name[:80]!r} took over {PATTERN_SECONDS:g} s (nested repeats "
      "such as (a+)+ backtrack without end); simplify the pattern"
    ) from None
  except regex.error as e:
    raise UserError(f"{where} = {pattern[:80]!r}: not a regular expression ({e})") from None


def read_labels(spec: str, take_names: list[str], where: str = "data.labels") -> Labels:
  """The labels of ``take_names`` from ``spec``: a CSV file (``.csv``: a header ``take,FIELD,...``, then one row
  per take) or a regular expression with named groups, searched in each take's name. A take neither names
  is refused in one line, naming it."""
  if spec.lower().endswith(".csv"):
    fields, table = _read_label_csv(spec, where)
    pattern = None
  else:
    try:
      compiled = regex.compile(spec)
    except regex.error as e:
      raise UserError(f"{where} = {spec[:80]!r}: not a regular expression ({e})") from None
    if not compiled.groupindex:
      raise UserError(f"{where} = {spec[:80]!r}: name the labels with groups, e.g. (?P<style>[^_]+)")
    fields, table, pattern = list(compiled.groupindex), {}, spec
  labels = Labels(dict.fromkeys(fields, ()), pattern, table)
  found = {}
  for name in take_names:
    got = labels.of_take(name)
    if got is None:
      how = "has no row in the labels file" if pattern is None else "does not match the labels pattern"
      raise UserError(f"{where}: take {name!r} {how}")
    for field, value in got.items():
      _check_label(value, f"{where}: take {name!r}: {field}")
    found[name] = got
  values = {f: tuple(sorted({str(t[f]) for t in found.values()})) for f in fields}
  return Labels(values, pattern, table)


def _read_label_csv(path: str, where: str) -> tuple[list[str], dict]:
  try:
    rows = list(csv.reader(io.StringIO(read_text(path, "labels"), newline="")))  # a quoted line break kept
  except FileNotFoundError:
    raise UserError(f"{where}: {path}: no such labels file") from None
  except (csv.Error, UnicodeDecodeError) as e:
    raise UserError(f"{where}: {path}: not a CSV file ({e})") from None
  if not rows or len(rows[0]) < 2 or rows[0][0].strip() != "take":
    raise UserError(f"{where}: {path}:1: the header must be take,FIELD[,FIELD...]")
  fields = [f.strip() for f in rows[0][1:]]
  for f in fields:
    _check_label(f, f"{where}: {path}:1: field")
    if f == "take" or fields.count(f) > 1:
      raise UserError(f"{where}: {path}:1: field {f!r} is named twice (the first column is take)")
  table: dict = {}
  for line, row in enumerate(rows[1:], start=2):
    if not row:
      continue
    if len(row) != len(rows[0]) or not all(c.strip() for c in row):
      raise UserError(f"{where}: {path}:{line}: expected {len(rows[0])} non-empty cells, got {len(row)}")
    take, labels = row[0].strip(), {f: c.strip() for f, c in zip(fields, row[1:])}
    if table.get(take, labels) != labels:
      raise UserError(f"{where}: {path}:{line}: take {take!r} has another row that says otherwise")
    table[take] = labels
  return fields, table


LABEL_SEPARATORS = ",=:\n\r"  # what --motion and --mix split labels on: no field or value may hold them


def _check_label(text: str, where: str) -> None:
  """A UserError unless ``text`` (a field's name or value) can be named by ``--motion`` and ``--mix``."""
  if not text or any(c in LABEL_SEPARATORS for c in text):
    raise UserError(f"{where} {text!r}: a label cannot be empty or hold , = : or a line break (--motion names it)")


def take_condition(labels: Labels | None, id_map: dict, name: str, default: int | None = None):
  """What conditions the model on the take ``name``: its id in ``id_map`` (``default`` for a take not in it;
  None: refused), or with ``labels`` the weights ``[M]`` of its labels (a take they cannot read: refused)."""
  if labels is None:
    if name not in id_map and default is None:
      raise UserError(f"{name}: not a take this run was trained on")
    return id_map.get(name, default)
  found = labels.of_take(name)
  if found is None:
    raise UserError(f"{name}: the run's labels do not say what this take is (data.labels)")
  return labels.vector(found)
