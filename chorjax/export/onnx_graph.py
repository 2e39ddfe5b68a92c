"""A jitted JAX function as an ONNX graph: its jaxpr, operation by operation, in ONNX operators.

``chorjax export`` writes a run's one-frame draw this way. The function is traced once at fixed shapes, and
each primitive of its jaxpr becomes the ONNX operators that compute the same thing (nested programs,
``custom_jvp``/``custom_vjp`` functions and ``jit`` calls are inlined); the parameters the function closes over
become the graph's initializers. A primitive with no translation here is refused by name, so no graph is
written that computes something else. The maintained exporter made for this (jax2onnx) pins an
orbax-checkpoint older than the one chorjax's checkpoints are written with, so it cannot be installed beside
it; what a recurrent draw uses is a small set of primitives.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence

import jax
import numpy as np
import onnx
from jax.extend.core import Literal

OPSET = 18

_UNARY = {
  "exp": "Exp",
  "log": "Log",
  "tanh": "Tanh",
  "logistic": "Sigmoid",
  "sqrt": "Sqrt",
  "abs": "Abs",
  "neg": "Neg",
  "sin": "Sin",
  "cos": "Cos",
  "floor": "Floor",
  "ceil": "Ceil",
  "sign": "Sign",
  "not": "Not",
  "stop_gradient": "Identity",
  "copy": "Identity",
  "copy_p": "Identity",
}
_BINARY = {
  "add": "Add",
  "sub": "Sub",
  "mul": "Mul",
  "div": "Div",
  "max": "Max",
  "min": "Min",
  "pow": "Pow",
  "lt": "Less",
  "gt": "Greater",
  "le": "LessOrEqual",
  "ge": "GreaterOrEqual",
  "eq": "Equal",
  "and": "And",
  "or": "Or",
}
_REDUCE = {"reduce_sum": "ReduceSum", "reduce_max": "ReduceMax", "reduce_min": "ReduceMin"}
_INLINED = {"jit", "pjit", "custom_jvp_call", "custom_vjp_call", "closed_call", "core_call", "remat"}


class Unsupported(ValueError):
  """The function uses an operation this translation does not write (named in the message)."""


def to_onnx(
  fn: Callable,
  args: Sequence[np.ndarray],
  input_names: Sequence[str],
  output_names: Sequence[str],
  *,
  doc: str = "",
):
  """``fn(*args)`` (arrays in, a flat sequence of arrays out) as an ``onnx.ModelProto`` whose inputs and
  outputs carry the given names, at the shapes and dtypes of ``args``."""
  closed = jax.make_jaxpr(fn)(*args)
  g = _Graph()
  env: dict = {}
  for var, const in zip(closed.jaxpr.constvars, closed.consts, strict=True):
    env[var] = g.const(np.asarray(const))
  inputs = []
  for var, name in zip(closed.jaxpr.invars, input_names, strict=True):
    env[var] = name
    inputs.append(_value_info(name, var.aval))
  _emit(g, closed.jaxpr, env)
  outputs = []
  for var, name in zip(closed.jaxpr.outvars, output_names, strict=True):
    g.node("Identity", [g.read(env, var)], [name])
    outputs.append(_value_info(name, var.aval))
  graph = onnx.helper.make_graph(g.nodes, "chorjax", inputs, outputs, initializer=g.initializers)
  model = onnx.helper.make_model(
    graph, opset_imports=[onnx.helper.make_opsetid("", OPSET)], producer_name="chorjax", doc_string=doc
  )
  model.ir_version = 8  # what onnxruntime 1.14+ and onnxruntime-web read
  onnx.checker.check_model(model, full_check=True)
  return model


def _value_info(name: str, aval):
  return onnx.helper.make_tensor_value_info(name, _onnx_type(aval.dtype), list(aval.shape))


def _onnx_type(dtype) -> int:
  return onnx.helper.np_dtype_to_tensor_dtype(np.dtype(dtype))


class _Graph:
  """The nodes and initializers written so far, with fresh names."""

  def __init__(self):
    self.nodes: list = []
    self.initializers: list = []
    self._names = (f"t{i}" for i in itertools.count())

  def fresh(self) -> str:
    return next(self._names)

  def node(self, op: str, inputs: list[str], outputs: list[str] | None = None, **attrs) -> str:
    outputs = outputs or [self.fresh()]
    self.nodes.append(onnx.helper.make_node(op, inputs, outputs, **attrs))
    return outputs[0]

  def const(self, value) -> str:
    name = self.fresh()
    value = np.asarray(value)
    if value.dtype == np.float64:
      value = value.astype(np.float32)
    self.initializers.append(onnx.numpy_helper.from_array(value, name))
    return name

  def ints(self, values) -> str:
    return self.const(np.asarray(values, np.int64))

  def read(self, env: dict, var) -> str:
    if isinstance(var, Literal):
      return self.const(np.asarray(var.val, dtype=getattr(var.aval, "dtype", None)))
    return env[var]


def _emit(g: _Graph, jaxpr, env: dict) -> None:
  for eqn in jaxpr.eqns:
    ins = [g.read(env, v) for v in eqn.invars]
    outs = _translate(g, eqn, ins)
    for var, name in zip(eqn.outvars, outs, strict=True):
      env[var] = name


def _inner(eqn):
  """The jaxpr a call-like primitive runs (closed or open)."""
  for key in ("jaxpr", "call_jaxpr", "fun_jaxpr"):
    inner = eqn.params.get(key)
    if inner is not None:
      return inner
  raise Unsupported(f"cannot export: {eqn.primitive.name} without an inner program")


def _translate(g: _Graph, eqn, ins: list[str]) -> list[str]:
  prim = eqn.primitive.name
  if prim in _INLINED:
    return _inline(g, eqn, ins)
  if prim in _UNARY:
    return [g.node(_UNARY[prim], ins)]
  if prim in _BINARY:
    return [g.node(_BINARY[prim], ins)]
  if prim in _REDUCE:
    return [g.node(_REDUCE[prim], [ins[0], g.ints(list(eqn.params["axes"]))], keepdims=0)]
  handler = _HANDLERS.get(prim)
  if handler is None:
    raise Unsupported(f"cannot export: the draw uses {prim!r}, which has no ONNX translation here")
  out = handler(g, eqn, ins)
  return out if isinstance(out, list) else [out]


def _inline(g: _Graph, eqn, ins):
  """A call (``jit``, ``custom_jvp_call``, ...): its program's operations, in place."""
  inner = _inner(eqn)
  jaxpr, consts = (inner.jaxpr, inner.consts) if hasattr(inner, "consts") else (inner, ())
  env = {v: g.const(np.asarray(c)) for v, c in zip(jaxpr.constvars, consts, strict=True)}
  env.update(zip(jaxpr.invars, ins, strict=True))
  _emit(g, jaxpr, env)
  return [g.read(env, v) for v in jaxpr.outvars]


def _integer_pow(g: _Graph, eqn, ins):
  y, dtype = int(eqn.params["y"]), eqn.outvars[0].aval.dtype
  if not 1 <= y <= 8:
    return g.node("Pow", [ins[0], g.const(np.asarray(y, dtype))])
  acc = ins[0]
  for _ in range(y - 1):
    acc = g.node("Mul", [acc, ins[0]])
  return acc


def _select_n(g: _Graph, eqn, ins):
  pred, *cases = ins
  if len(cases) != 2:
    raise Unsupported(f"cannot export: select_n of {len(cases)} cases")
  if eqn.invars[0].aval.dtype != np.bool_:
    pred = g.node("Cast", [pred], to=_onnx_type(np.bool_))
  return g.node("Where", [pred, cases[1], cases[0]])


def _iota(g: _Graph, eqn, ins):
  p = eqn.params
  shape, dim = tuple(p["shape"]), p["dimension"]
  values = np.broadcast_to(np.arange(shape[dim]).reshape([-1 if i == dim else 1 for i in range(len(shape))]), shape)
  return g.const(values.astype(p["dtype"]))


def _broadcast_in_dim(g: _Graph, eqn, ins):
  shape, dims = tuple(eqn.params["shape"]), tuple(eqn.params["broadcast_dimensions"])
  lifted = [1] * len(shape)
  for src, dst in enumerate(dims):
    lifted[dst] = eqn.invars[0].aval.shape[src]
  return g.node("Expand", [g.node("Reshape", [ins[0], g.ints(lifted)]), g.ints(shape)])


def _split(g: _Graph, eqn, ins):
  sizes = [int(s) for s in eqn.params["sizes"]]
  outs = [g.fresh() for _ in sizes]
  g.node("Split", [ins[0], g.ints(sizes)], outs, axis=int(eqn.params["axis"]))
  return outs


def _slice(g: _Graph, eqn, ins):
  start, limit = list(eqn.params["start_indices"]), list(eqn.params["limit_indices"])
  steps = list(eqn.params["strides"] or [1] * len(start))
  return g.node("Slice", [ins[0], g.ints(start), g.ints(limit), g.ints(list(range(len(start)))), g.ints(steps)])


def _argmax(g: _Graph, eqn, ins):
  (axis,) = eqn.params["axes"]
  index = g.node("ArgMax", ins, axis=int(axis), keepdims=0)  # the first of equal maxima, as lax.argmax
  return g.node("Cast", [index], to=_onnx_type(eqn.params["index_dtype"]))


def _stack(g: _Graph, eqn, ins):
  axis = int(eqn.params["axis"])
  return g.node("Concat", [g.node("Unsqueeze", [x, g.ints([axis])]) for x in ins], axis=axis)


def _one(value):
  return np.ones((), value)


_HANDLERS = {
  "ne": lambda g, e, ins: g.node("Not", [g.node("Equal", ins)]),
  "log1p": lambda g, e, ins: g.node("Log", [g.node("Add", [ins[0], g.const(_one(e.outvars[0].aval.dtype))])]),
  "rsqrt": lambda g, e, ins: g.node("Reciprocal", [g.node("Sqrt", ins)]),
  "square": lambda g, e, ins: g.node("Mul", [ins[0], ins[0]]),
  "rem": lambda g, e, ins: g.node("Mod", ins, fmod=1),  # the sign of the dividend, as lax.rem
  "clamp": lambda g, e, ins: g.node("Min", [g.node("Max", [ins[1], ins[0]]), ins[2]]),  # clamp(lo, x, hi)
  "convert_element_type": lambda g, e, ins: g.node("Cast", ins, to=_onnx_type(e.params["new_dtype"])),
  "reshape": lambda g, e, ins: g.node("Reshape", [ins[0], g.ints(e.outvars[0].aval.shape)]),
  "squeeze": lambda g, e, ins: g.node("Reshape", [ins[0], g.ints(e.outvars[0].aval.shape)]),
  "expand_dims": lambda g, e, ins: g.node("Reshape", [ins[0], g.ints(e.outvars[0].aval.shape)]),
  "transpose": lambda g, e, ins: g.node("Transpose", ins, perm=list(e.params["permutation"])),
  "concatenate": lambda g, e, ins: g.node("Concat", ins, axis=int(e.params["dimension"])),
  "cumsum": lambda g, e, ins: g.node(
    "CumSum", [ins[0], g.ints(int(e.params["axis"]))], reverse=int(e.params["reverse"])
  ),
  "integer_pow": _integer_pow,
  "select_n": _select_n,
  "iota": _iota,
  "broadcast_in_dim": _broadcast_in_dim,
  "split": _split,
  "stack": _stack,
  "slice": _slice,
  "argmax": _argmax,
}


def _dot_general(g: _Graph, eqn, ins):
  """``dot_general`` as an Einsum (batch dimensions, then the left's free ones, then the right's)."""
  (lc, rc), (lb, rb) = eqn.params["dimension_numbers"]
  nl, nr = (len(v.aval.shape) for v in eqn.invars)
  letters = iter("abcdefghijklmnopqrstuvwxyz")
  left = [next(letters) for _ in range(nl)]
  right = [""] * nr
  for i, j in zip(lb, rb, strict=True):
    right[j] = left[i]
  for i, j in zip(lc, rc, strict=True):
    right[j] = left[i]
  right = [r or next(letters) for r in right]
  batch = [left[i] for i in lb]
  free_l = [left[i] for i in range(nl) if i not in lb and i not in lc]
  free_r = [right[j] for j in range(nr) if j not in rb and j not in rc]
  spec = f"{''.join(left)},{''.join(right)}->{''.join(batch + free_l + free_r)}"
  if nl == 2 and nr == 2 and not lb and tuple(lc) == (1,) and tuple(rc) == (0,):
    out = g.node("MatMul", ins)
  else:
    out = g.node("Einsum", ins, equation=spec)
  want = eqn.outvars[0].aval.dtype
  return out if want == eqn.invars[0].aval.dtype else g.node("Cast", [out], to=_onnx_type(want))


def _dynamic_slice(g: _Graph, eqn, ins):
  """``dynamic_slice`` with XLA's clamping of each start into the operand."""
  x, *starts = ins
  shape = eqn.invars[0].aval.shape
  sizes = eqn.params["slice_sizes"]
  begin = []
  for s, dim, size in zip(starts, shape, sizes, strict=True):
    s64 = g.node("Cast", [s], to=_onnx_type(np.int64))
    clamped = g.node("Min", [g.node("Max", [s64, g.ints(0)]), g.ints(dim - size)])
    begin.append(g.node("Reshape", [clamped, g.ints([1])]))
  start = g.node("Concat", begin, axis=0)
  end = g.node("Add", [start, g.ints(list(sizes))])
  return g.node("Slice", [x, start, end, g.ints(list(range(len(shape))))])


def _gather(g: _Graph, eqn, ins):
  """The ``gather`` of indexing along one axis (``x[..., idx, ...]``, ``take_along_axis`` at batch 1):
  one collapsed dimension, full slices elsewhere; with leading batch dimensions, :func:`_batched_gather`."""
  dn = eqn.params["dimension_numbers"]
  operand = eqn.invars[0].aval.shape
  sizes = tuple(eqn.params["slice_sizes"])
  if dn.operand_batching_dims:
    return _batched_gather(g, eqn, ins)
  simple = (
    len(dn.collapsed_slice_dims) == 1
    and tuple(dn.start_index_map) == tuple(dn.collapsed_slice_dims)
    and not dn.operand_batching_dims
    and all(s == (1 if i == dn.collapsed_slice_dims[0] else d) for i, (s, d) in enumerate(zip(sizes, operand)))
  )
  if not simple:
    raise Unsupported(f"cannot export: a gather of the form {dn}")
  axis = dn.collapsed_slice_dims[0]
  idx_shape = eqn.invars[1].aval.shape
  index = g.node("Reshape", [ins[1], g.ints(idx_shape[:-1] or [])]) if idx_shape[-1] == 1 else None
  if index is None:
    raise Unsupported(f"cannot export: a gather with index vectors of {idx_shape[-1]}")
  index = g.node("Cast", [index], to=_onnx_type(np.int64))
  index = g.node("Max", [g.node("Min", [index, g.ints(operand[axis] - 1)]), g.ints(0)])  # in bounds, as XLA
  taken = g.node("Gather", [ins[0], index], axis=axis)
  # Gather gives operand[:axis] + batch + operand[axis + 1:]; XLA puts the offset dims where offset_dims says
  nb = len(idx_shape) - 1
  rest = [d for d in range(len(operand)) if d != axis]
  order = [("o", d) for d in rest[:axis]] + [("b", i) for i in range(nb)] + [("o", d) for d in rest[axis:]]
  out_rank = len(eqn.outvars[0].aval.shape)
  want, offsets, batches = [], iter(rest), iter(range(nb))
  for pos in range(out_rank):
    want.append(("o", next(offsets)) if pos in dn.offset_dims else ("b", next(batches)))
  perm = [order.index(w) for w in want]
  return taken if perm == sorted(perm) else g.node("Transpose", [taken], perm=perm)


def _batched_gather(g: _Graph, eqn, ins):
  """``take_along_axis`` over leading batch dimensions (``x[b, idx[b, ...], ...]``) as GatherND."""
  dn = eqn.params["dimension_numbers"]
  operand, idx_shape = eqn.invars[0].aval.shape, eqn.invars[1].aval.shape
  n = len(dn.operand_batching_dims)
  out_rank, rest = len(eqn.outvars[0].aval.shape), len(operand) - n - 1
  simple = (
    tuple(dn.operand_batching_dims) == tuple(dn.start_indices_batching_dims) == tuple(range(n))
    and tuple(dn.collapsed_slice_dims) == tuple(dn.start_index_map) == (n,)
    and idx_shape[-1] == 1
    and tuple(eqn.params["slice_sizes"]) == (1,) * (n + 1) + tuple(operand[n + 1 :])
    and tuple(dn.offset_dims) == tuple(range(out_rank - rest, out_rank))
  )
  if not simple:
    raise Unsupported(f"cannot export: a gather of the form {dn}")
  index = g.node("Cast", [ins[1]], to=_onnx_type(np.int64))
  index = g.node("Max", [g.node("Min", [index, g.ints(operand[n] - 1)]), g.ints(0)])  # in bounds, as XLA
  return g.node("GatherND", [ins[0], index], batch_dims=n)


def _scatter(g: _Graph, eqn, ins):
  """The ``scatter`` of ``x.at[i].set(v)`` and ``x.at[a:b].set(v)`` along the first axis (one index), and of
  ``x.at[..., idx].set(v)`` along any one axis (:func:`_scatter_along`)."""
  dn = eqn.params["dimension_numbers"]
  operand = eqn.invars[0].aval.shape
  update = eqn.invars[2].aval.shape
  one_axis = len(dn.scatter_dims_to_operand_dims) == 1 and dn.inserted_window_dims == dn.scatter_dims_to_operand_dims
  several = eqn.invars[1].aval.size > 1 or tuple(dn.scatter_dims_to_operand_dims) != (0,)
  if one_axis and several and not dn.operand_batching_dims:
    return _scatter_along(g, eqn, ins)
  if tuple(dn.scatter_dims_to_operand_dims) != (0,) or dn.operand_batching_dims or eqn.invars[1].aval.size != 1:
    raise Unsupported(f"cannot export: a scatter of the form {dn}")
  rows = 1 if dn.inserted_window_dims == (0,) else update[0]
  start = g.node("Cast", [g.node("Reshape", [ins[1], g.ints([1])])], to=_onnx_type(np.int64))
  start = g.node("Min", [g.node("Max", [start, g.ints(0)]), g.ints(operand[0] - rows)])
  index = g.node("Reshape", [g.node("Add", [start, g.ints(np.arange(rows))]), g.ints([rows, 1])])
  values = g.node("Reshape", [ins[2], g.ints([rows, *operand[1:]])])
  return g.node("ScatterND", [ins[0], index, values])


def _scatter_along(g: _Graph, eqn, ins):
  """``x.at[..., idx, ...].set(v)`` along one axis ``a``: ScatterND on ``x`` with ``a`` moved first."""
  dn = eqn.params["dimension_numbers"]
  operand, update = eqn.invars[0].aval.shape, eqn.invars[2].aval.shape
  (a,) = dn.scatter_dims_to_operand_dims
  idx_shape = eqn.invars[1].aval.shape
  if idx_shape[-1] != 1:
    raise Unsupported(f"cannot export: a scatter with index vectors of {idx_shape[-1]}")
  first = [a, *[d for d in range(len(operand)) if d != a]]
  back = [first.index(d) for d in range(len(operand))]
  data = g.node("Transpose", [ins[0]], perm=first)
  index = g.node("Cast", [ins[1]], to=_onnx_type(np.int64))
  window = list(dn.update_window_dims)
  batch = [d for d in range(len(update)) if d not in window]
  values = g.node("Transpose", [ins[2]], perm=batch + window)
  return g.node("Transpose", [g.node("ScatterND", [data, index, values])], perm=back)


_HANDLERS.update({"dot_general": _dot_general, "dynamic_slice": _dynamic_slice, "gather": _gather, "scatter": _scatter})
