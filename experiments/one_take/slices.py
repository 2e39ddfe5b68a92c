"""The single takes of the one-take benchmark: the first 20, 40 or 60 seconds of one take of a dancer, cut as a
user would cut a recording (the file's own format, its header kept), into runs/one_take/takes/.

  python experiments/one_take/slices.py      # from the repository root, ../shared beside it

cmu94: take 94_05 (41 s, bundled, CSV at 30 fps); salsa: take 09 (21.5 s, BVH at 120 fps); martial: take 06
(27.2 s, BVH at 120 fps); Bandai Namco's dance (63 s, BVH at 30 fps, CC BY-NC 4.0, read from ../shared). No take
of salsa or martial lasts 40 s: their 20 s slices stand in, and the Bandai dance gives the 40 and 60 s ones.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"
OUT = ROOT / "runs" / "one_take" / "takes"
SOURCES = {
  "cmu94": ROOT / "chorjax" / "data" / "bundled" / "cmu94" / "94_05_skeleton_3d.csv",
  "salsa": SHARED / "aclstm" / "salsa" / "09.bvh",
  "martial": SHARED / "aclstm" / "martial" / "06.bvh",
  "bandai": SHARED / "bvh" / "bandai" / "dataset-1_dance-short_normal_001.bvh",
}
SLICES = {"cmu94": (20, 40), "salsa": (20,), "martial": (20,), "bandai": (20, 40, 60)}


def bvh_slice(src: Path, dst: Path, seconds: float) -> int:
  """The first ``seconds`` of a BVH: its hierarchy, ``Frames:`` set to the frames kept."""
  lines = src.read_text().splitlines()
  i = next(k for k, line in enumerate(lines) if line.strip().startswith("Frames:"))
  n = round(seconds / float(lines[i + 1].split(":")[1]))
  if len(lines) - i - 2 < n:
    raise SystemExit(f"{src}: shorter than {seconds} s")
  dst.write_text("\n".join([*lines[:i], f"Frames: {n}", lines[i + 1], *lines[i + 2 : i + 2 + n]]) + "\n")
  return n


def csv_slice(src: Path, dst: Path, seconds: float, fps: float = 30.0) -> int:
  """The first ``seconds`` of a CSV take (one frame a row)."""
  lines = src.read_text().splitlines()
  n = round(seconds * fps)
  if len(lines) < n:
    raise SystemExit(f"{src}: shorter than {seconds} s")
  dst.write_text("\n".join(lines[:n]) + "\n")
  return n


if __name__ == "__main__":
  OUT.mkdir(parents=True, exist_ok=True)
  for dancer, seconds in SLICES.items():
    src = SOURCES[dancer]
    for s in seconds:
      dst = OUT / f"{dancer}_{s}s{src.suffix}"
      n = (bvh_slice if src.suffix == ".bvh" else csv_slice)(src, dst, s)
      print(f"{dst.relative_to(ROOT)}: {n} frames")
