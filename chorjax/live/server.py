"""``chorjax live``: the model dances without end, in real time, for a browser and for creative tools.

One asyncio process. A generator runs ahead of the clock in small jit-compiled chunks (in a worker
thread, so the event loop never waits on it); a pacer sends one frame every 1/fps seconds to every
WebSocket client and, with ``--osc``, as an OSC message; ``GET /`` serves the live player page. Clients
steer the dance with JSON messages; OSC can steer it too, and feed a dancer's own frames in.

Protocol (WebSocket at ``/ws``; every message is one JSON object):

- server -> client, first: ``{"hello": {"fps", "joints", "bones", "joint_names", "up_axis", "to_y_up", "floor",
  "motions", "settings"}}`` (``floor``: the training floor's height along the up axis, in the data's units; null
  where the run records none); then one message per frame, paced in real time:
  ``{"frame": n, "positions": [[x, y, z], ...], "source": "model" | "input"}`` (J joints, the data's
  units and axes; ``source`` is ``input`` while a dancer's frames are passed through, ``--alternate``).
- client -> server: ``{"prime": [[[x, y, z], ...], ...]}`` (a phrase of frames in data space: the model
  continues from its last frame, as ``chorjax sample --prime`` does), ``{"prime_file": {"name":
  "phrase.bvh", "text": "..."}}`` (a CSV/BVH/NPZ... file's text, read as training reads takes: the live
  page's "prime from file"), ``{"set": {"pi_temperature": t, "sigma_temperature": s, "mix":
  "4:0.5,5:0.5"}}`` (any of the three; a labelled run's mix: ``"style=elderly:0.5,style=active:0.5"``) and
  ``{"pause": true | false}``. Each gets ``{"ok": KIND}`` or ``{"error": "..."}`` back; the stream goes on
  either way.

OSC (UDP): with ``--osc HOST:PORT`` every frame is also sent as ``/chorjax/frame`` with J*3 floats
(x, y, z per joint). With ``--osc-in HOST:PORT`` chorjax listens for ``/chorjax/input`` (J*3 floats: one
frame of a dancer, for ``--alternate``), ``/chorjax/prime`` (P*J*3 floats: a phrase), ``/chorjax/set``
(name, value pairs: ``pi_temperature``, ``sigma_temperature``, ``mix``) and ``/chorjax/pause`` (1 or 0).

Latency: a ``set`` acts from the next chunk generated, so it becomes visible after the frames already
buffered ahead (at most ``AHEAD`` chunks of ``chunk`` frames: about 0.3 s at 30 fps); a prime clears the
buffer and is visible from the next frame after its chunk is drawn.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import json
import math
import signal
import tempfile
from pathlib import Path

import jax
import numpy as np

from chorjax.data.motion import Motion
from chorjax.data.transforms import up_axis_matrix
from chorjax.errors import UserError, check_output, load_json, refuse_existing
from chorjax.io.output import write_motions
from chorjax.live.guard import Budget, header_refusal, host_port, origin_refusal, server_names
from chorjax.render.html import live_html
from chorjax.run import load_run
from chorjax.sample import read_phrase
from chorjax.sampling.controls import Controls
from chorjax.sampling.table import check_sample_control

AHEAD = 2  # chunks generated ahead of the clock
PRIME_RANGE = 10.0  # a primed frame's features may lie this many times the training range's span outside it
MAX_MESSAGE = 4 * 2**20  # bytes of one client message (a prime of minutes of frames, a file's text)
MAX_FPS = 1000  # frames sent per second at most
MAX_TURN = 3600  # seconds of one turn of --alternate at most
CLOSE_TIMEOUT = 0.5  # seconds a client gets to answer the closing handshake when the server stops


class Stream:
  """An endless dance in data space, ``chunk`` frames at a time (not thread-safe: one caller at a time).

  Args:
    run: a loaded run (``chorjax.run.load_run``, ranged for the sampling).
    sampling: the sampling controls (``Run.sampling``).
    weights_M: the weights that condition the dance (``Run.motion_weights``).
    seed: the sampling seed.
    chunk: frames per generated chunk.
  """

  def __init__(self, run, sampling: Controls, weights_M, seed: int, chunk: int):
    self.run, self.features, self.chunk = run, run.features, chunk
    self.draw = sampling.draw(run.features)
    self.decoding = sampling.decoding()
    self.weights = np.asarray(weights_M, np.float32)
    self.key, self.count = jax.random.key(seed), 0
    self.keep = run.config.data.seq_length  # frames a re-prime teacher-forces
    self.history: collections.deque = collections.deque(maxlen=self.keep)
    self.last = None  # (normalized frame, data-space frame) the next chunk continues from
    self._start(None)

  def _start(self, prime_PxD) -> None:
    self.state = self._started(None if prime_PxD is None else np.asarray(prime_PxD, np.float32)[None])

  def _started(self, prime_1xPxD):
    start_stream, _ = self.run.family.stream()
    return start_stream(self.run.graphdef, self.run.params, self.weights[None], self._draw(), prime_1xPxD)

  def _draw(self):
    """The draw for the weights danced now (with labels, the governor holds their pace)."""
    return self.draw.for_motion(self.weights[None])

  def next_chunk(self) -> np.ndarray:
    """The next ``chunk`` frames ``[C, J, 3]`` in data space."""
    _, continue_stream = self.run.family.stream()
    key = jax.random.fold_in(self.key, self.count)
    self.count += 1
    self.state, z = continue_stream(
      self.run.graphdef, self.run.params, self.state, key, self._draw(), num_frames=self.chunk
    )
    z = np.asarray(z[0])
    if self.last is None:
      pos = np.asarray(self.features.decode(z, **self.decoding), np.float32)
    else:
      pos = self.features.decode_after(z, *self.last, **self.decoding)
    self.last = (z[-1], pos[-1])
    self.history.extend(z)
    return pos

  def prime(self, positions_PxJx3) -> None:
    """Continue from a phrase in data space ``[P, J, 3]`` (P >= 2): the model is teacher forced over it
    and the next chunk starts after its last frame, where that frame stands."""
    pos = np.asarray(positions_PxJx3, np.float32)
    j = self.features.skeleton.num_joints
    if pos.ndim != 3 or pos.shape[1:] != (j, 3) or len(pos) < 2:
      raise UserError(f"prime: expected at least 2 frames of {j} joints x 3, got shape {list(pos.shape)}")
    if not np.isfinite(pos).all():
      raise UserError("prime: positions must be finite numbers")
    pos = pos[-self.prime_length(len(pos)) :]  # a few compiled lengths: no client stalls the others
    with np.errstate(all="ignore"):  # absurd magnitudes overflow to inf here and are refused just below
      z = np.asarray(self.features.encode(pos), np.float32)
    f = self.features
    if f.low is not None and f.high is not None:
      span = np.asarray(f.high, np.float32) - np.asarray(f.low, np.float32)
      outside = (z < np.asarray(f.low) - PRIME_RANGE * span) | (z > np.asarray(f.high) + PRIME_RANGE * span)
      if not np.isfinite(z).all() or outside.any():
        raise UserError(f"prime: the phrase lies far outside the training data's range (over {PRIME_RANGE}x its span)")
    self._start(z)
    self.last = (z[-1], pos[-1])
    self.history.clear()
    self.history.extend(z)

  def prime_length(self, frames: int) -> int:
    """The frames of a phrase of ``frames`` that a prime keeps: the longest of ``keep`` and the powers of
    two below it that fits (older frames go), so primes run one of a few programs compiled in advance."""
    return max(n for n in self.prime_lengths() if n <= frames)

  def prime_lengths(self) -> list[int]:
    return sorted({self.keep, *(2**k for k in range(1, self.keep.bit_length()) if 2**k < self.keep)})

  def warm_up(self) -> None:
    """Compiles every prime length (``prime_lengths``; a new mix re-primes with ``keep`` frames), so a
    prime shows in a few frames instead of after a compile that would stall every viewer."""
    rest = np.asarray(self.features.decode(np.zeros((self.keep, self.features.dim), np.float32)), np.float32)
    z = np.asarray(self.features.encode(rest), np.float32)  # the mean pose, held: any phrase will do
    for n in self.prime_lengths():
      jax.block_until_ready(self._started(z[None, -n:]))

  def set(self, pi_temperature=None, sigma_temperature=None, mix=None) -> None:
    """New temperatures (from the next chunk) and/or a new motion mix (``"4:0.5,5:0.5"``): the model is
    conditioned on it and re-primed with the frames it just danced, so the dance changes without a jump."""
    given = {"pi_temperature": pi_temperature, "sigma_temperature": sigma_temperature}
    checked = {k: check_sample_control(k, v, f"set {k}") for k, v in given.items() if v is not None}
    weights = None if mix is None else self.run.motion_weights(mix=str(mix), source="mix")
    self.draw = self.draw.replace(**checked)
    if weights is not None:
      self.weights = weights
      self._start(np.asarray(self.history) if len(self.history) >= 2 else None)


class Live:
  """The server's state: clients, the frames generated ahead, the pacing, the recording."""

  def __init__(self, stream: Stream, fps: float, *, osc=None, alternate: float = 0.0, source=None):
    self.stream, self.fps = stream, fps
    self.clients: set = set()
    self.ahead: collections.deque = collections.deque()
    self.lock = asyncio.Lock()  # one stream call at a time (they run in a worker thread)
    self.paused = False
    self.sent: list[np.ndarray] = []
    self.osc = osc
    self.turn_frames = max(1, round(alternate * fps)) if alternate else 0
    self.source = source  # the input to alternate with: a Phrase or an OscInput (or None)
    self.received: list[np.ndarray] = []
    self.input_turn = False
    self.priming = False
    self.ticks = 0  # frame periods gone by, paused ones left out

  def hello(self) -> str:
    f, run = self.stream.features, self.stream.run
    sk = f.skeleton
    draw = self.stream.draw
    scalars = {f.name: getattr(draw, f.name) for f in dataclasses.fields(draw) if f.name != "pace_lag" or draw.pace}
    settings = {k: v for k, v in scalars.items() if isinstance(v, int | float | bool)}
    return json.dumps(
      {
        "hello": {
          "fps": self.fps,
          "joints": sk.num_joints,
          "bones": [list(b) for b in sk.bones],
          "joint_names": list(sk.joint_names),
          "up_axis": f.up_axis,
          "to_y_up": up_axis_matrix(f.up_axis).tolist(),  # the page draws y-up
          "floor": None if f.floor is None else f.floor / f.scale,  # the training floor's height, y-up data units
          "motions": run.num_motions,
          "settings": settings,
        }
      }
    )

  async def call(self, fn, *args, **kwargs):
    """``fn`` on the stream, in a worker thread, one call at a time."""
    async with self.lock:
      return await asyncio.to_thread(fn, *args, **kwargs)

  async def generate(self) -> None:
    """Keeps ``AHEAD`` chunks ready; the pacer takes frames from them."""
    while True:
      if len(self.ahead) < AHEAD * self.stream.chunk and not (self.input_turn or self.priming):
        self.ahead.extend(await self.call(self.stream.next_chunk))
      else:
        await asyncio.sleep(0.25 / self.fps)

  async def pace(self) -> None:
    """One frame every 1/fps seconds to every client (and OSC), on an absolute clock (no drift)."""
    broadcast = _net()[0].asyncio.server.broadcast
    loop = asyncio.get_running_loop()
    period, due = 1.0 / self.fps, loop.time()
    while True:
      due += period
      await asyncio.sleep(max(0.0, due - loop.time()))
      if loop.time() - due > period:  # late (a stall, a prime compiling): go on from now, never in a burst
        due = loop.time()
      if self.paused:
        continue
      self.ticks += 1
      if self.turn_frames and self.ticks % self.turn_frames == 0:  # turns go by the clock, sent or not
        self._switch_turn()
      frame, source = self._next_frame()
      if frame is None:
        continue
      message = {"frame": len(self.sent), "positions": np.round(frame, 5).tolist(), "source": source}
      broadcast(self.clients, json.dumps(message))
      if self.osc is not None:
        self.osc.send_message("/chorjax/frame", [float(v) for v in frame.reshape(-1)])
      self.sent.append(frame)

  def _next_frame(self):
    if self.priming:
      return None, None
    if not self.input_turn:
      return (self.ahead.popleft(), "model") if self.ahead else (None, None)
    frame = self.source.next() if self.source is not None else None
    if frame is not None:
      self.received.append(frame)
    return frame, "input"

  def _switch_turn(self) -> None:
    """``--alternate``: the input dances, then the model continues from what it received, in turns."""
    if self.source is None:
      return
    if self.input_turn and len(self.received) >= 2:
      phrase, self.received = np.stack(self.received), []
      self.priming = True  # nothing is sent until the model has taken the phrase in
      asyncio.get_running_loop().create_task(self.prime(phrase))
    self.input_turn = not self.input_turn

  async def prime(self, positions) -> None:
    try:
      await self.call(self.stream.prime, positions)
      self.ahead.clear()  # the continuation shows at once, not after the frames already drawn
    finally:
      self.priming = False

  async def handle(self, message, budget: Budget | None = None) -> str:
    """One client message -> the reply (``{"ok": KIND}`` or ``{"error": ...}``); past the client's ``budget``
    a message is answered, not served."""
    try:
      data = load_json(message)
    except (json.JSONDecodeError, UnicodeDecodeError, TypeError) as e:
      return json.dumps({"error": f"not JSON: {e}"})
    kinds = ("prime", "prime_file", "set", "pause")
    if not isinstance(data, dict) or len(data) != 1 or next(iter(data)) not in kinds:
      return json.dumps({"error": f"expected one of {', '.join(kinds)} as the only key"})
    kind, value = next(iter(data.items()))
    if budget is not None and not budget.take(kind):
      most = f"at most {Budget.RATES[kind]:g} a second (bursts of {Budget.BURST[kind]:g}) from one client"
      return json.dumps({"error": f"too many {kind} messages: {most}"})
    try:
      await self.apply(kind, value)
    except UserError as e:
      return json.dumps({"error": str(e)})
    return json.dumps({"ok": kind})

  async def apply(self, kind: str, value) -> None:
    if kind == "pause":
      if not isinstance(value, bool):
        raise UserError("pause: expected true or false")
      self.paused = value
    elif kind == "set":
      if not isinstance(value, dict) or not value or set(value) - {"pi_temperature", "sigma_temperature", "mix"}:
        raise UserError("set: expected an object with pi_temperature, sigma_temperature and/or mix")
      await self.call(self.stream.set, **value)
    elif kind == "prime":
      try:
        if not _all_numbers(value):  # not "1" or true, which numpy would take for numbers
          raise TypeError
        positions = np.asarray(value, np.float32)
      except (ValueError, TypeError):
        raise UserError("prime: expected frames of [x, y, z] per joint, numbers") from None
      await self.prime(positions)
    else:
      await self.prime(await asyncio.to_thread(self.read_file, value))

  def read_file(self, value) -> np.ndarray:
    """A ``prime_file`` message's file, read as training reads takes (any format chorjax reads)."""
    if not isinstance(value, dict) or not isinstance(value.get("name"), str) or not isinstance(value.get("text"), str):
      raise UserError('prime_file: expected {"name": "phrase.csv", "text": "..."}')
    suffix = Path(value["name"]).suffix.lower()
    with tempfile.TemporaryDirectory() as tmp:
      path = Path(tmp) / f"phrase{suffix}"
      try:
        path.write_text(value["text"], encoding="utf-8")
      except UnicodeEncodeError:  # a lone surrogate: JSON can carry one, no file can
        raise UserError(f"prime_file {value['name']!r}: the text holds a character that is not Unicode") from None
      try:
        return read_phrase(str(path), self.stream.features, self.stream.run.config.data, "prime_file")
      except UserError as e:
        raise UserError(str(e).replace(str(path), value["name"])) from None


def _all_numbers(value) -> bool:
  """Whether ``value`` (a message's JSON) is numbers in nested lists: no strings, booleans or nulls."""
  todo = [value]
  while todo:
    v = todo.pop()
    if isinstance(v, list):
      todo.extend(v)
    elif isinstance(v, bool) or not isinstance(v, (int, float)):
      return False
  return True


class Phrase:
  """A file's frames played as if live (``--input``): the next frame on each call, cycled."""

  def __init__(self, positions_TxJx3):
    self.positions, self.at = positions_TxJx3, 0

  def next(self) -> np.ndarray:
    frame = self.positions[self.at % len(self.positions)]
    self.at += 1
    return frame


class OscInput:
  """Frames arriving as OSC ``/chorjax/input`` (``--osc-in``): the oldest not yet passed on, or None."""

  def __init__(self, keep: int = 1000):
    self.frames: collections.deque = collections.deque(maxlen=keep)

  def next(self) -> np.ndarray | None:
    return self.frames.popleft() if self.frames else None


def _net():
  """``(websockets, pythonosc)`` with the parts live mode uses loaded: the live extra, imported here alone so
  that chorjax runs without it."""
  import pythonosc.dispatcher, pythonosc.osc_server, pythonosc.udp_client  # noqa: E401, I001  (the live extra)
  import websockets.asyncio.server, websockets.datastructures, websockets.http11  # noqa: E401  (the live extra)

  return websockets, pythonosc


async def serve(live: Live, host: str, port: int, *, osc_in=None, on_ready=print, origins=()) -> None:
  """Serves until SIGINT or SIGTERM; ``on_ready`` gets the line ``serving http://HOST:PORT``; WebSocket
  clients from other pages are refused (``origin_refusal``; ``origins``: more allowed)."""
  websockets = _net()[0]
  ws_serve, Headers, Response = (
    websockets.asyncio.server.serve,
    websockets.datastructures.Headers,
    websockets.http11.Response,
  )
  page = live_html(title=f"chorjax live ({live.stream.run.workdir})").encode("utf-8")

  names = server_names(host)

  def route(connection, request):
    malformed = header_refusal(request.headers)
    if malformed:
      print(f"chorjax live: refused a malformed request: {malformed}", flush=True)
      return connection.respond(400, f"malformed request: {malformed}\n")
    refused = origin_refusal(request.headers, host, origins, names)
    if refused:
      return connection.respond(403, f"refused: {refused}\n")
    path = request.path.split("?", 1)[0]  # a query string (?v=2, a cache buster) names the same page
    if path == "/ws":
      return None  # the WebSocket handshake goes on
    if path in ("/", "/index.html"):
      headers = Headers([("Content-Type", "text/html; charset=utf-8"), ("Content-Length", str(len(page)))])
      return Response(200, "OK", headers, page)
    return connection.respond(404, "not found: the page is at / and the stream at /ws\n")

  async def client(ws):
    live.clients.add(ws)
    budget = Budget()
    try:
      await ws.send(live.hello())
      async for message in ws:
        await ws.send(await live.handle(message, budget))
    except Exception:  # a client that goes away mid-message is its own business, never the stream's
      pass
    finally:
      live.clients.discard(ws)

  loop = asyncio.get_running_loop()
  stop = loop.create_future()
  for sig in (signal.SIGINT, signal.SIGTERM):
    loop.add_signal_handler(sig, lambda: stop.done() or stop.set_result(None))
  transport = await _listen_osc(live, *osc_in) if osc_in else None
  for _ in range(AHEAD):  # compiled (the first chunk and the continuing ones) before "serving"
    live.ahead.extend(await live.call(live.stream.next_chunk))
  await live.call(live.stream.warm_up)
  async with ws_serve(
    client, host, port, process_request=route, ping_interval=None, close_timeout=CLOSE_TIMEOUT, max_size=MAX_MESSAGE
  ) as server:
    bound = server.sockets[0].getsockname()[1] if server.sockets else port
    tasks = [asyncio.create_task(live.generate()), asyncio.create_task(live.pace())]
    on_ready(f"serving http://{host}:{bound}")
    await stop
    for t in tasks:
      t.cancel()
    server.close(close_connections=True)
  if transport is not None:
    transport.close()


async def _listen_osc(live: Live, host: str, port: int):
  """``--osc-in``: OSC messages steer the stream (see the module docstring)."""
  pythonosc = _net()[1]
  Dispatcher, AsyncIOOSCUDPServer = pythonosc.dispatcher.Dispatcher, pythonosc.osc_server.AsyncIOOSCUDPServer
  j3 = live.stream.features.skeleton.num_joints * 3
  loop = asyncio.get_running_loop()
  act = lambda kind, value: loop.create_task(_quietly(live.apply(kind, value)))

  def frames(values) -> np.ndarray | None:
    ok = len(values) >= j3 and len(values) % j3 == 0 and all(isinstance(v, int | float) for v in values)
    return np.asarray(values, np.float32).reshape(-1, j3 // 3, 3) if ok else None

  def on_input(_, *values):
    f = frames(values)
    if f is not None and len(f) == 1 and isinstance(live.source, OscInput):
      live.source.frames.append(f[0])

  def on_prime(_, *values):
    f = frames(values)
    if f is not None:
      act("prime", f)

  def on_set(_, *pairs):
    act("set", {str(k): v for k, v in zip(pairs[::2], pairs[1::2])})

  dispatcher = Dispatcher()
  dispatcher.map("/chorjax/input", on_input)
  dispatcher.map("/chorjax/prime", on_prime)
  dispatcher.map("/chorjax/set", on_set)
  dispatcher.map("/chorjax/pause", lambda _, on=1, *rest: act("pause", bool(on)))
  server = AsyncIOOSCUDPServer((host, port), dispatcher, loop)  # type: ignore[arg-type]  # any running loop
  transport, _ = await server.create_serve_endpoint()
  return transport


async def _quietly(coro) -> None:
  """An OSC command has no one to answer: a bad one is dropped (the stream goes on)."""
  with contextlib.suppress(UserError):
    await coro


def run_live(
  workdir,
  *,
  host: str = "127.0.0.1",
  port: int = 8765,
  fps: float | None = None,
  seed: int = 0,
  controls: dict | None = None,
  motion: int | None = None,
  mix: str | None = None,
  osc: str | None = None,
  osc_in: str | None = None,
  alternate: float = 0.0,
  input_spec: str | None = None,
  record=None,
  checkpoint="kept",
  on_ready=print,
  allow_origins=(),
  force: bool = False,
) -> int:
  """``chorjax live``: loads the run, serves until Ctrl-C, writes the recording (``record``, an ``.npz`` not
  replaced unless ``force``); returns 0."""
  _check_flags(port, record, force, fps, alternate)
  for origin in allow_origins:
    if not origin.isprintable() or " " in origin:
      raise UserError(f"--allow-origin {origin!r}: an origin has no spaces or control characters (CR, LF)")
  osc_out = host_port(osc, "--osc") if osc else None
  listen = host_port(osc_in, "--osc-in") if osc_in else None
  if alternate and not (input_spec or listen):
    raise UserError("--alternate: needs an input to alternate with (--input FILE or --osc-in HOST:PORT)")
  run = load_run(workdir, checkpoint).serving("live")
  sampling = run.sampling(**(controls or {}))
  run = run.ranged(sampling)
  weights = run.motion_weights(motion, mix)  # --motion ID or --mix ID:W,... (or labels); default 0
  rate = fps or run.fps
  source = Phrase(read_phrase(input_spec, run.features, run.config.data, "--input")) if input_spec else None
  source = source or (OscInput() if listen else None)
  stream = Stream(run, sampling, weights, seed, chunk=max(1, math.ceil(rate / 8)))
  sender = None
  if osc_out:
    sender = _net()[1].udp_client.SimpleUDPClient(*osc_out)
  live = Live(stream, rate, osc=sender, alternate=alternate, source=source)
  try:
    asyncio.run(serve(live, host, port, osc_in=listen, on_ready=on_ready, origins=tuple(allow_origins)))
  except OSError as e:  # the port is taken, the host is not this machine's
    raise UserError(f"cannot serve on {host}:{port}: {e.strerror or e}") from None
  finally:
    if record is not None and live.sent:
      f, settings = run.features, {"workdir": str(workdir), "seed": seed, "fps": rate, **sampling.to_dict()}
      sent = Motion(np.stack(live.sent), rate, f.skeleton, f.up_axis, units="data")
      write_motions(Path(record), [sent], settings=settings)
  return 0


def _check_flags(port: int, record, force: bool, fps, alternate: float) -> None:
  """``chorjax live``'s flags checked before anything is loaded: the port, the recording (an ``.npz`` that
  is not there yet, unless ``force``), the frame rate and the alternation's seconds; and the live extra."""
  if not 0 <= port <= 65535:
    raise UserError(f"--port {port}: must be at least 0" if port < 0 else f"--port {port}: must be at most 65535")
  if record is not None:
    check_output(record, (".npz",))
    refuse_existing([record], force)
  try:
    _net()
  except ImportError:
    raise UserError("chorjax live needs the live extra: pip install -e '.[live]'") from None
  if fps is not None and not (math.isfinite(fps) and 0 < fps <= MAX_FPS):
    raise UserError(f"--fps {fps}: must be a number above 0 and at most {MAX_FPS}")
  if not 0 <= alternate <= MAX_TURN:  # (NaN fails it too)
    raise UserError(f"--alternate {alternate}: must be a number of seconds from 0 to {MAX_TURN}")
  if record is not None:
    try:  # a file made and gone: what the end writes (os.access says yes to /proc for root)
      with tempfile.TemporaryFile(dir=Path(record).absolute().parent):
        pass
    except OSError:
      raise UserError(f"{record}: --record cannot be written there (no such folder, or not writable)") from None
