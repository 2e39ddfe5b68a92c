"""One self-contained, offline HTML file: a 3D stick-figure player for one or many motions.

No network and no CDN: the motions are embedded as base64 float32 arrays and drawn with a small
perspective projection on 2D canvases. Controls: play/pause, scrub bar, speed, mouse drag to orbit,
wheel to zoom. It starts playing (looped). Motions sit side by side, each in a labelled panel; panels
wrap onto further rows on narrow screens, and each canvas is sized to its box at the device pixel
ratio (crisp) and to the window's height (a dancer is never cut off below the fold).

Opening the file with ``#selftest`` appended plays it briefly and writes a JSON report into the
``<pre id="selftest">`` element (JavaScript errors, non-blank pixels, whether playing changed the
picture, the canvases' boxes and the window's size); the browser test reads it.
"""

from __future__ import annotations

import base64
import html as html_lib
import json
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chorjax.data import transforms
from chorjax.data.motion import Motion
from chorjax.errors import atomic_write


def _payload(m: Motion) -> dict:
  pos = np.asarray(transforms.to_y_up(m.positions, m.up_axis), np.float32)  # the viewer is y-up
  height = float(np.ptp(pos[..., 1])) or 1.0
  return {
    "title": m.name,
    "fps": m.fps,
    "frames": int(pos.shape[0]),
    "joints": int(pos.shape[1]),
    "bones": [list(b) for b in m.skeleton.bones],
    "scale": 2.0 / height,
    "data": base64.b64encode(np.ascontiguousarray(pos).tobytes()).decode("ascii"),
  }


def player_html(motions: Sequence[Motion], title: str = "chorjax", columns: int | None = None) -> str:
  """The player page as a string; ``columns`` fixes the grid's columns (default: as many side by side
  as fit, each at least 300 CSS pixels wide)."""
  grid = f"repeat({columns}, minmax(0, 1fr))" if columns else "repeat(auto-fit, minmax(min(100%, 300px), 1fr))"
  data = script_json([_payload(m) for m in motions])
  page = _fill(_TEMPLATE, STYLE=_STYLE, FIGURE=_FIGURE)  # our own parts first, then what came from outside
  return _fill(page, TITLE=html_lib.escape(_unicode(title)), GRID=grid, DATA=data)


def _unicode(text: str) -> str:
  """``text`` with any lone surrogate (what a file name's invalid byte decodes to) as U+FFFD: a page is UTF-8."""
  return text.encode("utf-16", "surrogatepass").decode("utf-16", "replace")


def script_json(value) -> str:
  """``value`` as JSON that is safe inside ``<script>``: ``<``, ``>``, ``&`` and the line separators
  U+2028/2029 written as ``\\uXXXX`` escapes (a name holding ``</script>`` or ``<!--`` cannot end or bend the
  script; JSON reads the escapes back as the same characters)."""
  text = json.dumps(value)
  for char in "<>&\u2028\u2029":
    text = text.replace(char, f"\\u{ord(char):04x}")
  return text


def _fill(template: str, **values: str) -> str:
  """``__NAME__`` placeholders replaced in ONE pass: text put in (a title) is never searched for more
  placeholders, so a title holding ``__DATA__`` stays text."""
  return re.sub(r"__([A-Z]+)__", lambda m: values[m.group(1)] if m.group(1) in values else m.group(0), template)


def live_html(title: str = "chorjax live") -> str:
  """The live page (``chorjax live`` serves it at ``/``): connects to the WebSocket at ``/ws`` on its own
  host and draws the dancer as frames arrive, with the player's look; controls for the temperatures, the
  motion mix, pause/resume and "prime from file". ``window.__live`` holds what a test reads (frames
  received, replies, errors)."""
  page = _fill(_LIVE, STYLE=_STYLE, FIGURE=_FIGURE)
  return _fill(page, TITLE=html_lib.escape(_unicode(title)), GRID="minmax(0, 1fr)")


def write_player(motions: Sequence[Motion], path, title: str = "chorjax", columns: int | None = None) -> Path:
  """Writes the player page atomically."""
  text = player_html(motions, title, columns)
  return atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"))


_STYLE = """<style>
body { font-family: system-ui, sans-serif; margin: 12px; background: #fafafa; color: #222; }
h3 { margin: 0 0 8px; }
#controls { display: flex; gap: 10px; align-items: center; margin-bottom: 10px; }
#scrub { flex: 1; }
#grid { display: grid; grid-template-columns: __GRID__; gap: 8px; }
figure { margin: 0; background: #fff; border: 1px solid #ddd; }
figcaption { font-size: 13px; padding: 4px 8px; border-bottom: 1px solid #eee; }
canvas { width: 100%; height: 360px; display: block; cursor: grab; }
</style>"""

# The stick figure's drawing, shared by the player and the live page: view, projection, canvas fit, one
# frame drawn, mouse orbit and zoom. A panel ``p`` holds ``m`` (joints, bones, scale), ``pos``, ``cx``/``cz``/``y0``.
_FIGURE = r"""  var view = { yaw: 0.6, pitch: 0.25, zoom: 1.5 };
  function project(p, x, y, z) {
    var s = p.m.scale; x = (x - p.cx) * s; y = (y - p.y0) * s - 1.0; z = (z - p.cz) * s;
    var cy = Math.cos(view.yaw), sy = Math.sin(view.yaw), cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
    var x1 = cy * x + sy * z, z1 = -sy * x + cy * z;
    var y2 = cp * y - sp * z1, z2 = sp * y + cp * z1;
    var d = 6.0 / view.zoom, f = Math.min(p.cv.height, p.cv.width * 1.25) * 1.1 / (d - z2);
    return [p.cv.width / 2 + x1 * f, p.cv.height / 2 - y2 * f];
  }
  function fit(players) {  // each canvas: its box's width, as tall as the window allows, at the device pixel ratio
    var dpr = window.devicePixelRatio || 1;
    players.forEach(function (p) {
      var top = p.cv.getBoundingClientRect().top + window.scrollY;
      var h = Math.max(160, Math.min(window.innerHeight - top - 14, p.cv.clientWidth * 1.25));
      p.cv.style.height = Math.floor(h) + 'px';
      p.cv.width = Math.round(p.cv.clientWidth * dpr); p.cv.height = Math.round(h * dpr); p.dpr = dpr;
    });
  }
  function draw(p, t) {  // frame t of p.pos (a camera that follows: p.camx / p.camz, its centre at each frame)
    var ctx = p.ctx, W = p.cv.width, H = p.cv.height, J = p.m.joints, px = p.dpr || 1;
    aim(p, t);
    ctx.fillStyle = '#ffffff'; ctx.fillRect(0, 0, W, H);
    ctx.strokeStyle = '#e4e4e4'; ctx.lineWidth = px;  // floor grid
    for (var g = -4; g <= 4; g++) {
      var a = proj3(p, g, 0, -4), b = proj3(p, g, 0, 4), c = proj3(p, -4, 0, g), d = proj3(p, 4, 0, g);
      line(ctx, a, b); line(ctx, c, d);
    }
    var base = t * J * 3, pts = [];
    for (var j = 0; j < J; j++) pts.push(project(p, p.pos[base + 3 * j], p.pos[base + 3 * j + 1], p.pos[base + 3 * j + 2]));
    ctx.strokeStyle = '#1f5fa8'; ctx.lineWidth = 3 * px;
    p.m.bones.forEach(function (bn) { line(ctx, pts[bn[0]], pts[bn[1]]); });
    ctx.fillStyle = '#c0392b';
    pts.forEach(function (q) { ctx.beginPath(); ctx.arc(q[0], q[1], 3 * px, 0, 2 * Math.PI); ctx.fill(); });
  }
  function aim(p, t) { if (p.camx) { p.cx = p.camx[t]; p.cz = p.camz[t]; } }  // a following camera, at frame t
  function proj3(p, gx, gy, gz) {  // grid lines in viewer units, fixed on the floor, around the camera's centre
    var cell = 1 / (p.m.scale * 2);
    return project(p, Math.round(p.cx / cell) * cell + gx * cell, p.y0, Math.round(p.cz / cell) * cell + gz * cell);
  }
  function line(ctx, a, b) { ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.stroke(); }
  function orbit(players, render) {  // mouse drag orbits, the wheel zooms
    players.forEach(function (p) {
      var drag = null;
      p.cv.addEventListener('mousedown', function (e) { drag = [e.clientX, e.clientY]; });
      window.addEventListener('mouseup', function () { drag = null; });
      window.addEventListener('mousemove', function (e) {
        if (!drag) return;
        view.yaw += (e.clientX - drag[0]) * 0.01; view.pitch = Math.max(-1.4, Math.min(1.4, view.pitch + (e.clientY - drag[1]) * 0.01));
        drag = [e.clientX, e.clientY]; render();
      });
      p.cv.addEventListener('wheel', function (e) { e.preventDefault(); view.zoom = Math.max(0.3, Math.min(5, view.zoom * (e.deltaY > 0 ? 0.9 : 1.1))); render(); }, { passive: false });
    });
  }
"""

_TEMPLATE = r"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>__TITLE__</title>
<script>window.__errors = []; window.addEventListener('error', function (e) { window.__errors.push(String(e.message)); });</script>
__STYLE__</head><body>
<h3>__TITLE__</h3>
<div id="controls">
  <button id="play">Play</button>
  <input id="scrub" type="range" min="0" max="0" value="0">
  <span id="frame">0</span>
  <label>speed <select id="speed"><option>0.25</option><option>0.5</option><option selected>1</option><option>2</option><option>4</option></select></label>
  <span style="font-size:12px;color:#777">drag: orbit, wheel: zoom</span>
</div>
<div id="grid"></div>
<pre id="selftest"></pre>
<script>
(function () {
  var MOTIONS = __DATA__;
  function decode(b64) {
    var s = atob(b64), bytes = new Uint8Array(s.length);
    for (var i = 0; i < s.length; i++) bytes[i] = s.charCodeAt(i);
    return new Float32Array(bytes.buffer);
  }
  var players = MOTIONS.map(function (m) {
    var fig = document.createElement('figure');
    var cap = document.createElement('figcaption'); cap.textContent = m.title + ' (' + m.frames + ' frames, ' + m.fps + ' fps)';
    var cv = document.createElement('canvas');
    fig.appendChild(cap); fig.appendChild(cv); document.getElementById('grid').appendChild(fig);
    var pos = decode(m.data), J = m.joints, ymin = Infinity, T = m.frames, half = Math.round(m.fps);
    var sx = new Float64Array(T + 1), sz = new Float64Array(T + 1), camx = new Float32Array(T), camz = new Float32Array(T);
    for (var t = 0; t < T; t++) {  // the camera follows the dancer: the first joint's mean over about 2 s around t
      sx[t + 1] = sx[t] + pos[(t * J) * 3]; sz[t + 1] = sz[t] + pos[(t * J) * 3 + 2];
      for (var j = 0; j < J; j++) ymin = Math.min(ymin, pos[(t * J + j) * 3 + 1]);
    }
    for (var u = 0; u < T; u++) {
      var a = Math.max(0, u - half), b = Math.min(T, u + half + 1);
      camx[u] = (sx[b] - sx[a]) / (b - a); camz[u] = (sz[b] - sz[a]) / (b - a);
    }
    return { m: m, cv: cv, ctx: cv.getContext('2d'), pos: pos, cx: camx[0], cz: camz[0], camx: camx, camz: camz, y0: ymin };
  });
  var maxFrames = Math.max.apply(null, MOTIONS.map(function (m) { return m.frames; }));
  var fps = MOTIONS.length ? MOTIONS[0].fps : 30;
  var scrub = document.getElementById('scrub'); scrub.max = Math.max(0, maxFrames - 1);
  var state = { frame: 0, playing: false, last: 0 };

__FIGURE__
  function render() { players.forEach(function (p) { draw(p, Math.min(state.frame, p.m.frames - 1)); }); scrub.value = state.frame; document.getElementById('frame').textContent = state.frame; }
  function setPlaying(on) { state.playing = on; state.last = performance.now(); document.getElementById('play').textContent = on ? 'Pause' : 'Play'; }
  document.getElementById('play').onclick = function () { setPlaying(!state.playing); };
  scrub.oninput = function () { state.frame = parseInt(scrub.value, 10); render(); };
  var acc = 0;
  setInterval(function () {
    if (!state.playing) return;
    var now = performance.now(), speed = parseFloat(document.getElementById('speed').value);
    acc += (now - state.last) / 1000 * fps * speed; state.last = now;
    var step = Math.floor(acc);
    if (step > 0) { acc -= step; state.frame = (state.frame + step) % maxFrames; render(); }
  }, 15);
  orbit(players, render);
  fit(players); render();
  window.addEventListener('resize', function () { fit(players); render(); });
  setPlaying(true);  // autoplay, looped

  var at = /^#selftest(?:@(\d+))?$/.exec(location.hash);  // #selftest@N: from frame N
  if (at) {
    if (at[1]) { state.frame = Math.min(parseInt(at[1], 10), maxFrames - 1); render(); }
    var signature = function () {
      var sig = 0, nonblank = 0;
      players.forEach(function (p) {
        var d = p.ctx.getImageData(0, 0, p.cv.width, p.cv.height).data;
        for (var i = 0; i < d.length; i += 4) {
          if (d[i] < 200 || d[i + 1] < 200) { nonblank++; sig = (sig * 31 + i) % 1000000007; }
        }
      });
      return [sig, nonblank];
    };
    var before = signature(), f0 = state.frame;
    setTimeout(function () {
      setPlaying(false);
      var after = signature();
      document.getElementById('selftest').textContent = JSON.stringify({
        errors: window.__errors, nonblank: before[1], changed: before[0] !== after[0], frames: [f0, state.frame],
        viewport: [window.innerWidth, window.innerHeight],
        boxes: players.map(function (p) { var r = p.cv.getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; }),
        pixels: players.map(function (p) { return [p.cv.width, p.cv.height]; }),
        inside: players.map(function (p) {  // the share of the figure's joints on its canvas at the last frame
          var t = Math.min(state.frame, p.m.frames - 1), J = p.m.joints, n = 0;
          aim(p, t);
          for (var j = 0; j < J; j++) {
            var q = project(p, p.pos[(t * J + j) * 3], p.pos[(t * J + j) * 3 + 1], p.pos[(t * J + j) * 3 + 2]);
            if (q[0] >= 0 && q[0] <= p.cv.width && q[1] >= 0 && q[1] <= p.cv.height) n++;
          }
          return n / J;
        })
      });
    }, 700);
  }
})();
</script></body></html>
"""


_LIVE = r"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>__TITLE__</title>
<script>window.__errors = []; window.addEventListener('error', function (e) { window.__errors.push(String(e.message)); });</script>
__STYLE__
<style>
#controls { flex-wrap: wrap; font-size: 13px; }
#controls input[type=range] { width: 110px; }
#status { font-size: 12px; color: #777; }
</style></head><body>
<h3>__TITLE__</h3>
<div id="controls">
  <button id="pause">Pause</button>
  <label>mixture temperature <input id="pi" type="range" min="0" max="2" step="0.05"> <span id="piv"></span></label>
  <label>scale temperature <input id="sigma" type="range" min="0" max="2" step="0.05"> <span id="sigmav"></span></label>
  <label>mix <input id="mix" size="12" placeholder="4:0.5,5:0.5"></label><button id="setmix">Set</button>
  <label>prime from file <input id="prime" type="file" accept=".csv,.bvh,.npz,.amc,.c3d"></label>
  <span id="status">connecting...</span>
</div>
<div id="grid"></div>
<script>
(function () {
  window.__live = { frames: 0, replies: [], errors: window.__errors, connected: false };
__FIGURE__
  var p = null, toYUp = null, ws = null, paused = false, shown = 0, started = performance.now();
  var status = document.getElementById('status');
  function say(text) { status.textContent = text; }
  function send(obj) { if (ws && ws.readyState === 1) ws.send(JSON.stringify(obj)); }
  function render() { if (p) draw(p, 0); }

  function setup(hello) {  // one panel, fed one frame at a time; the camera follows the dancer slowly
    var fig = document.createElement('figure'), cap = document.createElement('figcaption'), cv = document.createElement('canvas');
    cap.textContent = 'live (' + hello.joints + ' joints, ' + hello.fps + ' fps)';
    fig.appendChild(cap); fig.appendChild(cv); document.getElementById('grid').appendChild(fig);
    p = { m: { joints: hello.joints, bones: hello.bones, scale: 1, frames: 1 }, cv: cv, ctx: cv.getContext('2d'),
          pos: new Float32Array(hello.joints * 3), cx: 0, cz: 0, y0: 0, fresh: true };
    toYUp = hello.to_y_up;
    ['pi', 'sigma'].forEach(function (id) {
      var key = id === 'pi' ? 'pi_temperature' : 'sigma_temperature', el = document.getElementById(id);
      el.value = hello.settings[key]; document.getElementById(id + 'v').textContent = el.value;
      el.onchange = function () { document.getElementById(id + 'v').textContent = el.value; var s = {}; s[key] = parseFloat(el.value); send({ set: s }); };
    });
    fit([p]); orbit([p], render);
  }
  function frame(msg) {
    var J = p.m.joints, ymin = Infinity, ymax = -Infinity, root = 0;
    for (var j = 0; j < J; j++) {
      var q = msg.positions[j], r = toYUp;
      for (var a = 0; a < 3; a++) p.pos[3 * j + a] = r[a][0] * q[0] + r[a][1] * q[1] + r[a][2] * q[2];
      ymin = Math.min(ymin, p.pos[3 * j + 1]); ymax = Math.max(ymax, p.pos[3 * j + 1]);
    }
    var mx = 0, mz = 0;
    for (j = 0; j < J; j++) { mx += p.pos[3 * j] / J; mz += p.pos[3 * j + 2] / J; }
    if (p.fresh) { p.m.scale = 2.0 / Math.max(ymax - ymin, 1e-6); p.cx = mx; p.cz = mz; p.y0 = ymin; p.fresh = false; }
    var k = 0.02;  // the camera glides after the dancer (about 1.5 s at 30 fps)
    p.cx += k * (mx - p.cx); p.cz += k * (mz - p.cz); p.y0 += k * (ymin - p.y0);
    window.__live.frames++; shown = msg.frame;
    render();
    var secs = (performance.now() - started) / 1000;
    say('frame ' + msg.frame + (msg.source === 'input' ? ' (input)' : '') + ', ' + (window.__live.frames / secs).toFixed(1) + ' frames/s');
  }
  function connect() {
    ws = new WebSocket((location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/ws');
    ws.onopen = function () { window.__live.connected = true; say('connected'); };
    ws.onclose = function () { window.__live.connected = false; say('disconnected: reload to reconnect'); };
    ws.onmessage = function (e) {
      var msg = JSON.parse(e.data);
      if (msg.hello) { setup(msg.hello); started = performance.now(); }
      else if (msg.positions) { if (p) frame(msg); }
      else { window.__live.replies.push(msg); if (msg.error) say('error: ' + msg.error); }
    };
  }
  document.getElementById('pause').onclick = function () {
    paused = !paused; send({ pause: paused }); this.textContent = paused ? 'Resume' : 'Pause';
  };
  document.getElementById('setmix').onclick = function () { send({ set: { mix: document.getElementById('mix').value } }); };
  document.getElementById('prime').onchange = function () {
    var f = this.files[0]; if (!f) return;
    var reader = new FileReader();
    reader.onload = function () { send({ prime_file: { name: f.name, text: String(reader.result) } }); say('priming from ' + f.name); };
    reader.readAsText(f);
  };
  window.addEventListener('resize', function () { if (p) { fit([p]); render(); } });
  connect();
})();
</script></body></html>
"""
