"""The PyTorch peer a user would otherwise write: nn.LSTM / nn.GRU stacks, an LN-LSTM (its time loop in
Python, TorchScript-scripted, or with a ``torch.compile``d cell), MSE and MDN heads, and eager sampling
loops. Only the benchmarks import torch."""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn


class LNLSTMCell(nn.Module):
  """Layer norm on the input and recurrent gate pre-activations and on the cell state (Ba et al.)."""

  def __init__(self, d_in: int, h: int):
    super().__init__()
    self.h = h
    self.wx, self.wh = nn.Linear(d_in, 4 * h), nn.Linear(h, 4 * h, bias=False)
    self.ln_x, self.ln_h, self.ln_c = nn.LayerNorm([4, h]), nn.LayerNorm([4, h]), nn.LayerNorm(h)

  def forward(self, xp_t: Tensor, c: Tensor, h: Tensor) -> tuple[Tensor, Tensor]:
    z = xp_t + self.ln_h(self.wh(h).view(-1, 4, self.h))
    i, f, g, o = z[:, 0], z[:, 1], z[:, 2], z[:, 3]
    c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
    return c, torch.sigmoid(o) * torch.tanh(self.ln_c(c))


class LNLSTMLayer(nn.Module):
  """One layer over a whole sequence: the input projection and its layer norm hoisted out of the time loop
  (as chorjax does), the loop over frames in Python (eager) or in TorchScript (when scripted)."""

  def __init__(self, d_in: int, h: int):
    super().__init__()
    self.cell = LNLSTMCell(d_in, h)

  def forward(self, x: Tensor) -> Tensor:  # [B, T, D]
    b, t = x.shape[0], x.shape[1]
    xp = self.cell.ln_x(self.cell.wx(x).view(b, t, 4, self.cell.h))
    c = torch.zeros(b, self.cell.h, dtype=x.dtype, device=x.device)
    h = c
    outs: list[Tensor] = []
    for k in range(t):
      c, h = self.cell(xp[:, k], c, h)
      outs.append(h)
    return torch.stack(outs, 1)


class LNLSTM(nn.Module):
  def __init__(self, d_in: int, h: int, layers: int):
    super().__init__()
    self.layers = nn.ModuleList([LNLSTMLayer(d_in if l == 0 else h, h) for l in range(layers)])

  def forward(self, x: Tensor) -> Tensor:
    for layer in self.layers:
      x = layer(x)
    return x


def ln_lstm(d_in: int, h: int, layers: int, variant: str = "eager") -> nn.Module:
  """The LN-LSTM stack in the form ``variant`` names: ``eager`` (the Python loop), ``script``
  (``torch.jit.script`` of the whole stack, time loop included, as PyTorch's own custom-RNN benchmarks
  write it) or ``compile`` (``torch.compile`` of each step's cell; the loop stays in Python, which keeps
  the compile to one small graph instead of an unrolled 100-step one)."""
  stack = LNLSTM(d_in, h, layers)
  if variant == "script":
    return torch.jit.script(stack)
  if variant == "compile":
    for layer in stack.layers:
      layer.cell = torch.compile(layer.cell, dynamic=False)
    return stack
  if variant != "eager":
    raise ValueError(f"unknown LN-LSTM variant {variant!r}")
  return stack


class Model(nn.Module):
  def __init__(self, cell, head, d=48, h=256, layers=3, k=8, variant="eager"):
    super().__init__()
    self.cell, self.head, self.d, self.k = cell, head, d, k
    if cell == "lstm":
      self.rnn = nn.LSTM(d, h, layers, batch_first=True)
    elif cell == "gru":
      self.rnn = nn.GRU(d, h, layers, batch_first=True)
    else:
      self.rnn = ln_lstm(d, h, layers, variant)
    self.out = nn.Linear(h, d if head == "mse" else k + 2 * k * d)

  def forward(self, x):
    y = self.rnn(x)
    return self.out(y[0] if isinstance(y, tuple) else y)

  def loss(self, raw, target):
    if self.head == "mse":
      return ((raw - target) ** 2).mean()
    k, d = self.k, self.d
    logits, mu, scale = raw.split([k, k * d, k * d], -1)
    mu, scale = mu.unflatten(-1, (k, d)), nn.functional.softplus(scale.unflatten(-1, (k, d))).clamp_min(1e-3)
    z = (target.unsqueeze(-2) - mu) / scale
    comp = -0.5 * (z * z).sum(-1) - scale.log().sum(-1) - 0.5 * d * math.log(2 * math.pi)
    return -torch.logsumexp(torch.log_softmax(logits, -1) + comp, -1).mean()


def make_train_step(model):
  opt = torch.optim.Adam(model.parameters(), 1e-3)

  def step(x, y):
    opt.zero_grad(set_to_none=True)
    loss = model.loss(model(x), y)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), 10.0)
    opt.step()
    return loss

  return step


def mdn_draw(raw, k, d):
  logits, mu, scale = raw.split([k, k * d, k * d], -1)
  comp = torch.distributions.Categorical(logits=logits).sample()
  mu = mu.unflatten(-1, (k, d))[torch.arange(raw.shape[0]), comp]
  scale = nn.functional.softplus(scale.unflatten(-1, (k, d)))[torch.arange(raw.shape[0]), comp].clamp_min(1e-3)
  return mu + scale * torch.randn_like(mu)


@torch.no_grad()
def sample_lstmcell_loop(cells, out, frames, batch, d=48, k=8):
  """The fastest eager loop: a stack of nn.LSTMCell, one Python iteration per frame."""
  x = torch.zeros(batch, d)
  states = [(torch.zeros(batch, c.hidden_size), torch.zeros(batch, c.hidden_size)) for c in cells]
  for _ in range(frames):
    inp = x
    for l, cell in enumerate(cells):
      h, c = cell(inp, states[l])
      states[l] = (h, c)
      inp = h
    x = mdn_draw(out(inp), k, d)
  return x


@torch.no_grad()
def sample_lstm_loop(lstm, out, frames, batch, d=48, k=8):
  """The plain loop: nn.LSTM called on one frame at a time with its state carried."""
  x = torch.zeros(batch, 1, d)
  state = None
  for _ in range(frames):
    y, state = lstm(x, state)
    x = mdn_draw(out(y[:, 0]), k, d).unsqueeze(1)
  return x
