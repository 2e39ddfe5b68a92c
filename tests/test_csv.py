"""CSV motion I/O on the real CMU subject 94 takes, and every malformed-file error."""

import numpy as np
import pytest

from chorjax import cli
from chorjax.data.csv import read_csv, write_csv
from chorjax.data.dataset import bundled_path, resolve_files
from chorjax.errors import UserError

FRAMES = {"01": 830, "02": 771, "03": 820, "04": 716, "05": 1238, "06": 526, "07": 505, "08": 648, "09": 930, "10": 740}


def test_bundled_takes_match_their_sources_note():
  files = resolve_files("cmu94")
  assert [f.name[3:5] for f in files] == sorted(FRAMES)
  for f in files:
    m = read_csv(f)
    assert m.positions.shape == (FRAMES[f.name[3:5]], 16, 3)
    assert m.positions.dtype == np.float32
    assert m.up_axis == "-y" and m.skeleton.name == "mpii16"
    # y points down: feet lower on screen = larger y than the head top
    assert m.positions[:, [0, 5], 1].mean() > m.positions[:, 9, 1].mean()
  assert (bundled_path("cmu94") / "SOURCES.md").read_text().count("mocap.cs.cmu.edu") >= 1


def test_bundled_takes_equal_the_shared_originals(shared_data):
  for f in resolve_files("cmu94"):
    assert f.read_bytes() == (shared_data / "cmu94" / f.name).read_bytes()


def test_write_then_read_round_trips(tmp_path):
  m = read_csv(resolve_files("cmu94")[6])
  out = write_csv(m, tmp_path / "copy.csv")
  back = read_csv(out)
  np.testing.assert_allclose(back.positions, m.positions, rtol=1e-6)


GOOD_ROW = ",".join(["1.5"] * 48)


@pytest.mark.parametrize(
  "text, line, fragment",
  [
    (GOOD_ROW + "\n" + ",".join(["1"] * 47) + "\n", 2, "expected 48 columns"),
    (GOOD_ROW + "\n" + GOOD_ROW + ",7\n", 2, "found 49"),
    (GOOD_ROW + "\n" + GOOD_ROW + "\n" + GOOD_ROW.replace("1.5", "abc", 1) + "\n", 3, "not a number: 'abc'"),
    (GOOD_ROW.replace("1.5", "nan", 1) + "\n", 1, "non-finite"),
    (GOOD_ROW + "\n" + GOOD_ROW.replace("1.5", "inf", 2) + "\n", 2, "non-finite"),
    ("", None, "empty file"),
    ("\n\n", None, "empty file"),
  ],
)
def test_malformed_csv_errors_name_file_and_line(tmp_path, capsys, text, line, fragment):
  path = tmp_path / "bad.csv"
  path.write_text(text)
  with pytest.raises(UserError) as e:
    read_csv(path)
  msg = str(e.value)
  assert msg.startswith(f"{path}:{line}:" if line else f"{path}:") and fragment in msg
  # The CLI prints exactly that one line and exits 2.
  assert cli.main(["data", "info", str(path)]) == 2
  err = capsys.readouterr().err
  assert err.count("\n") == 1 and fragment in err and "Traceback" not in err


def test_a_take_shorter_than_a_window_is_left_out_and_named_and_all_of_them_are_refused(tmp_path):
  from chorjax.config import load_config
  from chorjax.data.dataset import dataset_notes, load_dataset

  moving = lambda t: ",".join(str(float(v) + 0.01 * t) for v in GOOD_ROW.split(","))
  (tmp_path / "a.csv").write_text("\n".join(moving(t) for t in range(30)))
  (tmp_path / "b.csv").write_text("\n".join(moving(t) for t in range(5)))
  cfg = load_config(None, [f"data.dataset={str(tmp_path)!r}", "data.seq_length=10", "data.val_takes=[]"])
  ds = load_dataset(cfg.data)
  assert [m.name for m in ds.motions] == ["a"]
  assert (
    "warning: 1 of 2 takes are shorter than one window (data.seq_length + 1 = 11 frames) and are left out: b (5); "
    "a shorter data.seq_length keeps them" in dataset_notes(ds)
  )
  cfg = load_config(None, [f"data.dataset={str(tmp_path)!r}", "data.seq_length=40"])
  with pytest.raises(UserError, match=r"a\.csv: 30 frames, shorter than one window"):
    load_dataset(cfg.data)
  # looped up to a window (data.loop), a take needs only a step: one frame is refused as that, not as a window
  (tmp_path / "a.csv").write_text(moving(0))
  (tmp_path / "b.csv").write_text(moving(0))
  cfg = load_config(None, [f"data.dataset={str(tmp_path)!r}", "data.seq_length=10", "data.loop=1.0"])
  with pytest.raises(UserError, match=r"a\.csv: 1 frames, shorter than two frames \(data\.loop"):
    load_dataset(cfg.data)
