"""The PyTorch peer a user would otherwise write: nn.LSTM / nn.GRU stacks, an LN-LSTM cell looped in
Python, MSE and MDN heads, and eager sampling loops. Only the benchmarks import torch."""

from __future__ import annotations

import math

import torch
from torch import nn


class LNLSTMCell(nn.Module):
  """Layer norm on the input and recurrent gate pre-activations and on the cell state (Ba et al.)."""

  def __init__(self, d_in, h):
    super().__init__()
    self.h = h
    self.wx, self.wh = nn.Linear(d_in, 4 * h), nn.Linear(h, 4 * h, bias=False)
    self.ln_x, self.ln_h, self.ln_c = (
      nn.LayerNorm([4, h]),
      nn.LayerNorm([4, h], elementwise_affine=True),
      nn.LayerNorm(h),
    )

  def forward(self, xp_t, state):
    c, h = state
    z = xp_t + self.ln_h(self.wh(h).view(-1, 4, self.h))
    i, f, g, o = z.unbind(1)
    c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
    return c, torch.sigmoid(o) * torch.tanh(self.ln_c(c))


class LNLSTM(nn.Module):
  def __init__(self, d_in, h, layers):
    super().__init__()
    self.cells = nn.ModuleList([LNLSTMCell(d_in if l == 0 else h, h) for l in range(layers)])

  def forward(self, x):  # [B, T, D]
    for cell in self.cells:
      b, t, _ = x.shape
      xp = cell.ln_x(cell.wx(x).view(b, t, 4, cell.h))  # hoisted, like chorjax
      c = h = x.new_zeros(b, cell.h)
      outs = []
      for k in range(t):
        c, h = cell(xp[:, k], (c, h))
        outs.append(h)
      x = torch.stack(outs, 1)
    return x


class Model(nn.Module):
  def __init__(self, cell, head, d=48, h=256, layers=3, k=8):
    super().__init__()
    self.cell, self.head, self.d, self.k = cell, head, d, k
    if cell == "lstm":
      self.rnn = nn.LSTM(d, h, layers, batch_first=True)
    elif cell == "gru":
      self.rnn = nn.GRU(d, h, layers, batch_first=True)
    else:
      self.rnn = LNLSTM(d, h, layers)
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
