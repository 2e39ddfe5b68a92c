"""Who may talk to ``chorjax live``: the ``--host``/``--port`` values, the server's own names, the Host and Origin
headers a WebSocket handshake must carry (a page of another site is refused, a DNS rebinding too) and the
per-client budget of costly commands (primes, settings)."""

from __future__ import annotations

import contextlib
import re
import socket
import time
import typing

from chorjax.errors import UserError

HOST_HEADER = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+)(:[0-9]{1,5})?")  # RFC 9110 Host, no user info


class Budget:
  """What one client may send a second, by kind: a prime re-starts the shared stream, so a client sending
  thousands would starve every other viewer; past its budget a message gets an error reply and is not served."""

  RATES: typing.ClassVar[dict[str, float]] = {"prime": 4.0, "prime_file": 2.0, "set": 30.0, "pause": 30.0}
  BURST: typing.ClassVar[dict[str, float]] = {"prime": 16.0, "prime_file": 4.0, "set": 60.0, "pause": 60.0}

  def __init__(self, clock=None):
    self.clock = clock or time.monotonic
    self.tokens = dict(self.BURST)
    self.at = dict.fromkeys(self.RATES, self.clock())

  def take(self, kind: str) -> bool:
    now, rate = self.clock(), self.RATES[kind]
    self.tokens[kind] = min(self.BURST[kind], self.tokens[kind] + (now - self.at[kind]) * rate)
    self.at[kind] = now
    if self.tokens[kind] < 1:
      return False
    self.tokens[kind] -= 1
    return True


def host_port(text: str, flag: str) -> tuple[str, int]:
  """``HOST:PORT`` (or ``PORT``, on 127.0.0.1) -> ``(host, port)``; a bad one is a UserError."""
  host, _, port = text.rpartition(":")
  if not port.isdigit() or not 0 <= int(port) < 65536:
    raise UserError(f"{flag} {text}: expected HOST:PORT, e.g. 127.0.0.1:9000")
  return host or "127.0.0.1", int(port)


LOOPBACK = {"127.0.0.1", "localhost", "::1", "[::1]"}


def server_names(host: str) -> set[str]:
  """The names a request's ``Host`` may use for a server listening on ``host``: loopback names alone on
  loopback; off it, also the listening address, this machine's host names and its addresses."""
  names = set(LOOPBACK)
  if host in LOOPBACK:
    return names
  if host not in ("", "0.0.0.0", "::"):
    names.add(host)
  names |= {socket.gethostname(), socket.getfqdn()}
  with contextlib.suppress(OSError):
    names |= {str(info[4][0]) for info in socket.getaddrinfo(socket.gethostname(), None)}
  with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
    s.connect(("192.0.2.1", 9))  # no packet is sent: this only picks the outgoing interface's address
    names.add(s.getsockname()[0])
  return {n.lower() for n in names}


def _host_name(hostport: str) -> str:
  """``evil.example:8765`` -> ``evil.example``; ``[::1]:8765`` -> ``[::1]``; the scheme of an origin dropped."""
  hostport = hostport.split("://", 1)[-1].lower()
  return hostport if hostport.endswith("]") else hostport.rsplit(":", 1)[0] if ":" in hostport else hostport


def header_refusal(headers) -> str | None:
  """Why a request's headers are malformed for this server (one ``Host``, at most one ``Origin``), or None."""
  hosts, origins = headers.get_all("Host"), headers.get_all("Origin")
  if len(hosts) != 1 or len(origins) > 1:
    return f"{len(hosts)} Host and {len(origins)} Origin headers (expected one Host and at most one Origin)"
  if not HOST_HEADER.fullmatch(hosts[0]):  # a name or address and a port: no user info (a@b), no spaces
    return f"Host {hosts[0]!r} is not a host name and port"
  return None


def origin_refusal(headers, host: str, allowed=(), names=None) -> str | None:
  """Why a WebSocket handshake with these request ``headers`` is refused, or None to accept it.

  Browsers send ``Origin`` with every WebSocket handshake, and any page the user has open may open one:
  only the page this server serves (Origin ``http://`` + the request's own Host) is let in, and programs
  that send no Origin (a script, a creative tool). ``allowed`` adds origins (``null`` for a page opened from
  a file, ``*`` for any). The Host must name this server (``server_names``: a loopback name when it listens
  on loopback) or an allowed origin's host, so a foreign domain resolved to this machine (DNS rebinding) is
  refused too, on loopback and off it. ``names``: the server's names, computed once by the caller.
  """
  origin, host_header = headers.get("Origin"), headers.get("Host", "")
  known = (server_names(host) if names is None else names) | {_host_name(a) for a in allowed}
  if _host_name(host_header) not in known:
    return f"Host {host_header!r} is not this server (chorjax live --allow-origin http://{host_header} lets it in)"
  if origin is None or "*" in allowed or origin in allowed:
    return None
  if origin == f"http://{host_header}":
    return None
  return f"Origin {origin!r} is not this server's page (chorjax live --allow-origin ORIGIN lets it in)"
