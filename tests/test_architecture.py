"""The package's shape: imports run one way (no cycle, imports inside functions included) and every
function stays short enough to read at once."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "chorjax"
MAX_FUNCTION_LINES = 70


def _module_name(path: Path) -> str:
  parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
  return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, modules: set[str]) -> set[str]:
  """The chorjax modules that ``path`` imports anywhere in its body (inside functions too)."""
  found = set()
  for node in ast.walk(ast.parse(path.read_text())):
    if isinstance(node, ast.Import):
      names = [a.name for a in node.names]
    elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
      # `from chorjax import checkpoint` imports the module chorjax.checkpoint
      names = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
    else:
      continue
    found |= {n for n in names if n in modules}
  return found


def import_graph() -> dict[str, set[str]]:
  files = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
  graph = {m: _imports(p, set(files)) - {m} for m, p in files.items()}
  # importing chorjax.a.b runs chorjax/__init__ and chorjax/a/__init__: a package depends on nothing here
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


def test_no_import_cycle_among_chorjax_modules():
  graph = import_graph()
  assert "chorjax.training" in graph["chorjax.evaluate"]  # the parser sees real imports
  assert find_cycle(graph) is None, f"import cycle: {' -> '.join(find_cycle(graph) or [])}"


def test_dependencies_run_one_way_from_data_to_the_command_line():
  graph = import_graph()
  assert "chorjax.training" not in graph["chorjax.sample"] and "chorjax.sample" not in graph["chorjax.run"]
  assert not graph["chorjax.run"] & {"chorjax.training", "chorjax.sample", "chorjax.cli"}
  below_models = {m for m in graph if m.startswith(("chorjax.models", "chorjax.data"))}
  for m in below_models:
    assert not graph[m] & {"chorjax.run", "chorjax.training", "chorjax.sample", "chorjax.cli"}, m


def test_no_function_is_longer_than_70_lines():
  long = []
  for path in PACKAGE.rglob("*.py"):
    for node in ast.walk(ast.parse(path.read_text())):
      if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
        n = node.end_lineno - node.lineno + 1
        if n > MAX_FUNCTION_LINES:
          long.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name} ({n} lines)")
  assert not long, "functions over 70 lines: " + ", ".join(long)
