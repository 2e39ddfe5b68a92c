"""The package's shape: imports run one way (no cycle, imports inside functions included), model families
are parts that plug in (nothing outside ``chorjax/families/`` names one), no two modules share a file name,
and every function stays short enough to read at once."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "chorjax"
MAX_FUNCTION_LINES = 70
MAX_MODULE_LINES = 600  # a module a reader takes in at one sitting


def _module_name(path: Path) -> str:
  parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
  return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _runtime_nodes(tree: ast.AST):
  """Every node of ``tree`` but those under ``if TYPE_CHECKING:`` (imports for annotations, never run)."""
  todo = [tree]
  while todo:
    node = todo.pop()
    yield node
    if not (isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING"):
      todo.extend(ast.iter_child_nodes(node))


def _imports(path: Path, modules: set[str]) -> set[str]:
  """The chorjax modules that ``path`` imports anywhere in its body (inside functions too)."""
  found = set()
  for node in _runtime_nodes(ast.parse(path.read_text())):
    if isinstance(node, ast.Import):
      names = [a.name for a in node.names]
    elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
      # `from chorjax import checkpoint` imports the module chorjax.checkpoint; `from chorjax import
      # __version__` runs the package root's code for a name it defines
      named = [f"{node.module}.{a.name}" for a in node.names]
      names = named + ([node.module] if not all(n in modules for n in named) or node.module != "chorjax" else [])
    else:
      continue
    found |= {n for n in names if n in modules}
  return found | {p for n in found for p in _parents(n) if p in modules}


def _parents(module: str) -> list[str]:
  """The packages whose ``__init__`` importing ``module`` runs, the root's aside (it loads the API only when
  one of its names is asked for, which ``from chorjax import NAME`` counts as an import of the root)."""
  parts = module.split(".")
  return [".".join(parts[:i]) for i in range(2, len(parts))]


def import_graph() -> dict[str, set[str]]:
  files = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
  graph = {m: _imports(p, set(files)) - {m} for m, p in files.items()}
  # a module inside a package runs its package's __init__ first: an edge from the package to the module
  # would be an import of its own parents, not a cycle
  return {m: {d for d in deps if not m.startswith(d + ".")} for m, deps in graph.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
  state: dict[str, int] = {}  # 1 = on the current path, 2 = done
  path: list[str] = []

  def visit(m):
    state[m] = 1
    path.append(m)
    for d in sorted(graph.get(m, ())):
      if state.get(d) == 1:
        return [*path[path.index(d) :], d]
      if d not in state and (cycle := visit(d)):
        return cycle
    state[m] = 2
    path.pop()
    return None

  for m in sorted(graph):
    if m not in state and (cycle := visit(m)):
      return cycle
  return None


def test_the_cycle_finder_finds_a_cycle():
  assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
  assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_the_graph_sees_edges_through_parent_packages(tmp_path):
  code = tmp_path / "m.py"
  code.write_text("from chorjax import __version__\nfrom chorjax import checkpoint\n")
  assert _imports(code, {"chorjax", "chorjax.checkpoint"}) == {"chorjax", "chorjax.checkpoint"}
  code.write_text("from chorjax import checkpoint\n")
  assert _imports(code, {"chorjax", "chorjax.checkpoint"}) == {"chorjax.checkpoint"}
  graph = import_graph()
  assert "chorjax.families" in graph["chorjax.run"]  # from chorjax.families.family import Family runs it
  assert "chorjax.evaluation" in graph["chorjax.api"]


def test_no_import_cycle_among_chorjax_modules():
  graph = import_graph()
  assert "chorjax.run" in graph["chorjax.evaluation.evaluate"]  # the parser sees real imports
  assert find_cycle(graph) is None, f"import cycle: {' -> '.join(find_cycle(graph) or [])}"


# The package's floors, lowest first: a module imports only modules on its own floor or below. A package sits
# on one floor, but for the two that hold both a role's parts and the command that uses them: sampling (the
# controls' table and their resolution low, the calibration's search of a run high) and evaluation (the
# measures low, ``chorjax eval`` high). A module takes the floor of its longest prefix here.
LAYERS = (
  ("chorjax.errors", "chorjax.fields", "chorjax.registry", "chorjax.checkpoint", "chorjax.blender_addon"),
  ("chorjax.data", "chorjax.models", "chorjax.sampling", "chorjax.sampling.table", "chorjax.sampling.calibration_file"),
  ("chorjax.runtime", "chorjax.sampling.controls", "chorjax.render"),
  ("chorjax.sections", "chorjax.config", "chorjax.optimizer"),
  ("chorjax.families", "chorjax.evaluation"),
  ("chorjax.run", "chorjax.io"),
  ("chorjax.sampling.calibrate", "chorjax.evaluation.evaluate", "chorjax.sample", "chorjax.training")
  + ("chorjax.export", "chorjax.live"),
  ("chorjax.sweeps", "chorjax.compare"),
  ("chorjax.api", "chorjax"),
  ("chorjax.cli_parser", "chorjax.cli"),
)


def floor_of(module: str, layers=LAYERS) -> int:
  """The floor of the longest prefix of ``module`` in ``layers`` (a ``KeyError`` for a module on none); the
  root (``chorjax``: what ``from chorjax import NAME`` runs) is a prefix of itself alone."""
  named = {p: i for i, floor in enumerate(layers) for p in floor}
  prefixes = [p for p in named if module == p or ("." in p and module.startswith(p + "."))]
  if not prefixes:
    raise KeyError(f"{module} is on no floor of LAYERS")
  return named[max(prefixes, key=len)]


def upward(graph: dict[str, set[str]], layers=LAYERS) -> list[str]:
  """Every import from a lower floor to a higher one."""
  return [f"{m} -> {d}" for m, deps in graph.items() for d in deps if floor_of(d, layers) > floor_of(m, layers)]


def test_the_floor_check_finds_an_upward_import():
  layers = (("p.low",), ("p.high", "p.low.top"))
  assert upward({"p.low.a": {"p.high"}, "p.high": {"p.low.a"}}, layers) == ["p.low.a -> p.high"]
  assert upward({"p.low.top": {"p.high"}, "p.high.x": {"p.low"}}, layers) == []
  with pytest.raises(KeyError, match=r"chorjax\.new is on no floor"):
    floor_of("chorjax.new")


def test_imports_run_down_the_floors_from_the_command_line_to_data():
  graph = import_graph()
  assert not upward(graph), "imports from a lower floor to a higher one: " + ", ".join(upward(graph))
  assert floor_of("chorjax.sampling.table") < floor_of("chorjax.sections") < floor_of("chorjax.run")
  assert floor_of("chorjax.data.formats") < floor_of("chorjax.render.drawers") < floor_of("chorjax.io.output")


def test_no_function_is_longer_than_70_lines():
  long = []
  for path in PACKAGE.rglob("*.py"):
    for node in ast.walk(ast.parse(path.read_text())):
      if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
        n = node.end_lineno - node.lineno + 1
        if n > MAX_FUNCTION_LINES:
          long.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name} ({n} lines)")
  assert not long, "functions over 70 lines: " + ", ".join(long)


def test_no_module_is_longer_than_600_lines():
  long = [
    f"{p.relative_to(PACKAGE.parent)} ({n})"
    for p in PACKAGE.rglob("*.py")
    if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES
  ]
  assert not long, "modules over 600 lines (split by role): " + ", ".join(long)


FAMILIES = PACKAGE / "families"


def _family_words() -> set[str]:
  from chorjax.registry import BUILTIN

  return set(BUILTIN)


def family_mentions(path: Path, words: set[str]) -> list[str]:
  """Where ``path`` names a family: imports a family's package (the registry and the ``Family`` base class are
  for all), compares a value with a family's name, or
  reads a ``Run.is_<family>`` flag."""
  found = []
  for node in ast.walk(ast.parse(path.read_text())):
    modules = []
    if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
      modules = [node.module] if node.module != "chorjax.families" else [f"{node.module}.{a.name}" for a in node.names]
    elif isinstance(node, ast.Import):
      modules = [a.name for a in node.names]
    family = [m for m in modules if m.startswith("chorjax.families.") and m.split(".")[2] in words | FOLDERS]
    found += [f"{path.name}:{node.lineno} imports {m}" for m in family[:1]]
    if isinstance(node, ast.Compare):
      consts = [c.value for c in [node.left, *node.comparators] if isinstance(c, ast.Constant)]
      found += [f"{path.name}:{node.lineno} compares with {c!r}" for c in consts if c in words]
    if isinstance(node, ast.Attribute) and node.attr.startswith("is_") and node.attr[3:] in words:
      found.append(f"{path.name}:{node.lineno} reads .{node.attr}")
    if isinstance(node, ast.Attribute) and node.attr in words:  # a family's config section: cfg.gan
      found.append(f"{path.name}:{node.lineno} reads the section .{node.attr}")
  return found


FOLDERS = {p.name for p in FAMILIES.iterdir() if p.is_dir() and p.name != "__pycache__"}


def test_the_family_check_finds_a_branch(tmp_path):
  code = tmp_path / "m.py"
  code.write_text("from chorjax.families.gan import networks\nif cfg.model.family == 'gan':\n  x = run.is_gan\n")
  assert len(family_mentions(code, {"gan", "rnn"})) == 3
  code.write_text("lr = cfg.gan.generator_lr\n")
  assert len(family_mentions(code, {"gan", "rnn"})) == 1
  code.write_text("from chorjax.families import family_of\nfrom chorjax.families.family import Family\n")
  assert family_mentions(code, {"gan", "rnn"}) == []


def test_no_module_outside_the_families_names_a_family():
  words = _family_words()
  outside = [p for p in PACKAGE.rglob("*.py") if FAMILIES not in p.parents]  # the config schema included
  found = [m for p in outside for m in family_mentions(p, words)]
  assert not found, "family named outside chorjax/families/: " + ", ".join(found)


def test_no_two_modules_share_a_file_name():
  seen: dict[str, list[str]] = {}
  for p in PACKAGE.rglob("*.py"):
    if p.name != "__init__.py":
      seen.setdefault(p.name, []).append(str(p.relative_to(PACKAGE.parent)))
  assert not {k: v for k, v in seen.items() if len(v) > 1}


CLI = PACKAGE / "cli.py"
PARSER = PACKAGE / "cli_parser.py"  # the command line's parser, for the handlers in cli.py
MAX_HANDLER_LINES = 15


def test_the_command_line_imports_the_api_and_nothing_else_of_chorjax():
  for path, own in ((CLI, {"chorjax.cli_parser"}), (PARSER, set())):
    found = _imports(path, set(import_graph())) - own
    assert found == {"chorjax.api"} or found == {"chorjax.api", "chorjax"}, (path.name, found)


def test_every_command_handler_is_short():
  """A handler parses, calls one API function and prints: the parser's set_defaults(func=NAME) names each, and
  cli.HANDLERS maps NAME to the function ``_NAME`` of cli.py."""
  names = {
    kw.value.value
    for node in ast.walk(ast.parse(PARSER.read_text()))
    if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "set_defaults"
    for kw in node.keywords
    if kw.arg == "func" and isinstance(kw.value, ast.Constant)
  }
  assert len(names) >= 15  # the parser is read
  from chorjax.cli import HANDLERS

  assert set(HANDLERS) == names and all(HANDLERS[n].__name__ == f"_{n}" for n in names)
  functions = {n.name: n for n in ast.parse(CLI.read_text()).body if isinstance(n, ast.FunctionDef)}
  long = {n: functions[f"_{n}"].end_lineno - functions[f"_{n}"].lineno + 1 for n in names}
  assert not {h: n for h, n in long.items() if n > MAX_HANDLER_LINES}, long


TABLE = PACKAGE / "sampling" / "table.py"
# The draw's jitted form (``controls.Draw``: traced and static fields, made from the controls by name).
COMPILED = {"Draw"}


def control_lists(path: Path, names: set[str]) -> list[str]:
  """Where ``path`` lists three or more sampling controls by name: a literal list, tuple, set or dict, the
  keywords of one call, or the fields of a class (a function's parameters are where controls act)."""
  found = []
  for node in ast.walk(ast.parse(path.read_text())):
    if isinstance(node, (ast.List, ast.Tuple, ast.Set, ast.Dict)):
      items = node.keys if isinstance(node, ast.Dict) else node.elts
      named = {e.value for e in items if isinstance(e, ast.Constant) and e.value in names}
    elif isinstance(node, ast.Call):
      named = {k.arg for k in node.keywords} & names
    elif isinstance(node, ast.ClassDef) and node.name not in COMPILED:
      named = {s.target.id for s in node.body if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)}
      named &= names
    else:
      continue
    if len(named) >= 3:
      found.append(f"{path.name}:{node.lineno} {sorted(named)}")
  return found


def test_the_control_list_finder_finds_lists(tmp_path):
  code = tmp_path / "m.py"
  listed = "A = ('pace', 'clamp', 'ground')\nf(pace=1, clamp=2, ground=3)\n"
  code.write_text(listed + "class C:\n  pace: int\n  clamp: int\n  ground: int\n")
  assert len(control_lists(code, {"pace", "clamp", "ground"})) == 3
  code.write_text("def f(pace, clamp, ground):\n  return {'pace': pace, 'clamp': clamp}\n")
  assert control_lists(code, {"pace", "clamp", "ground"}) == []


def test_the_sampling_controls_are_listed_once():
  """Flags, config keys, help, the calibration grid, plain draw and the ONNX graph's inputs are all made from
  ``chorjax.sampling.table``: no second list of the controls anywhere in the package."""
  from chorjax.sampling.table import NAMES

  lists = [
    f"{p.parent.name}/{hit}"
    for p in sorted(PACKAGE.rglob("*.py"))
    if p != TABLE
    for hit in control_lists(p, set(NAMES))
  ]
  assert not lists, "sampling controls listed outside chorjax/sampling/table.py: " + "; ".join(lists)


MAX_INNER_IMPORTS = 20


def test_imports_sit_at_the_top_but_a_few_that_say_why():
  """An import inside a function hides an arrow from a reader; the few left load an optional extra or keep
  ``import chorjax`` light, and say so on their line."""
  inner, silent = 0, []
  for path in PACKAGE.rglob("*.py"):
    if "blender_addon" in path.parts:  # runs inside Blender, on its own Python
      continue
    lines = path.read_text().splitlines()
    for fn in ast.walk(ast.parse("\n".join(lines))):
      if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
        for node in ast.walk(fn):
          if isinstance(node, (ast.Import, ast.ImportFrom)):
            inner += 1
            if "#" not in lines[node.lineno - 1]:
              silent.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}")
  assert inner <= MAX_INNER_IMPORTS, f"{inner} imports inside functions (at most {MAX_INNER_IMPORTS})"
  assert not silent, "imports inside functions that do not say why: " + ", ".join(silent)


def test_no_module_takes_a_public_name_of_the_package():
  """``chorjax.train`` is the API's function: a subpackage of that name, once imported, would take its place."""
  import pkgutil

  import chorjax

  modules = {m.name for m in pkgutil.iter_modules(chorjax.__path__)}
  assert not modules & set(chorjax.__all__), modules & set(chorjax.__all__)
  import chorjax.api

  assert callable(chorjax.train) and callable(chorjax.score)
