"""Named labels (``data.labels``) on a handful of Bandai Namco takes (``dataset-2_{action}_{style}_{trial}``, read
from ``../shared/data``): the run is conditioned on action and style instead of take ids, and is asked for
them from the command line, the API and live."""

import json
import tarfile
from pathlib import Path

import numpy as np
import pytest
from helpers import tiny_config

from chorjax import cli
from chorjax.api import load_run
from chorjax.data.dataset import WindowSampler, dataset_notes, load_dataset
from chorjax.data.features import takes_joint_pace
from chorjax.data.labels import read_labels
from chorjax.errors import UserError
from chorjax.export.dancer import OnnxDancer, sample_numbers
from chorjax.live.server import Stream
from chorjax.sample import sample_dancers
from chorjax.training.driver import train_and_evaluate

ARCHIVE = "bandai-motion.tar.xz"
TAKES = [f"dataset-2_{a}_{s}_{t:03d}" for a in ("walk", "run") for s in ("elderly", "active") for t in (1, 2)]
PATTERN = r"_(?P<action>[^_]+)_(?P<style>[^_]+)_\d+$"
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def takes(tmp_path_factory, shared_data):
  """Eight takes of the library: walk and run, elderly and active, two trials each."""
  where = tmp_path_factory.mktemp("bandai")
  wanted = {f"bandai-motion/{t}.bvh" for t in TAKES}
  members = []
  with tarfile.open(shared_data / ARCHIVE) as tar:
    for m in tar:  # an xz archive is read from its start: stop once the last wanted take is out
      if m.name in wanted:
        tar.extract(m, where, filter="data")
        members.append(m)
        if len(members) == len(wanted):
          break
  assert len(members) == len(TAKES)
  return where / "bandai-motion"


@pytest.fixture(scope="module")
def labelled_run(takes, tmp_path_factory):
  run_dir = tmp_path_factory.mktemp("labelled") / "run"
  # the shipped recipe for a labelled library at toy sizes: its labels pattern, its held-out trial 001 of every
  # label (4 of the 8 takes), the labels beside every frame, a length in passes over the data
  cfg = tiny_config(
    f"data.dataset={takes}",
    "train.epochs=0.5",
    "train.eval_every=1",
    "train.calibrate=false",
    "log.tensorboard=false",
    path=ROOT / "configs" / "library.toml",
  )
  assert cfg.data.labels == PATTERN and cfg.model.condition_every_frame
  train_and_evaluate(cfg, run_dir)
  run = load_run(run_dir)
  assert run.val_takes == tuple(t for t in sorted(TAKES) if t.endswith("_001")) and run.step >= 3
  return run_dir


def test_labels_from_names_or_a_csv_make_one_weight_per_value_and_each_take_one_per_field(takes, tmp_path):
  ds = load_dataset(tiny_config(f"data.dataset={takes}", f"data.labels={PATTERN}").data)
  assert ds.labels.fields == {"action": ("run", "walk"), "style": ("active", "elderly")}
  assert list(ds.id_map) == ["action=run", "action=walk", "style=active", "style=elderly"]
  assert "conditioned on labels (data.labels), not take ids: action (2): run, walk; style (2): active, elderly" in (
    dataset_notes(ds)
  )
  for name, (cond, _) in zip(ds.train_names, ds.train, strict=True):  # no augmentation in the tiny config
    action, style = name.split("_")[1:3]
    np.testing.assert_array_equal(cond, [action == "run", action == "walk", style == "active", style == "elderly"])
  batch = WindowSampler(ds.train, 12, 4, 0).batch(0)
  assert batch["motion_ids"].shape == (4, 4) and (batch["motion_ids"].sum(1) == 2).all()

  table = tmp_path / "labels.csv"
  table.write_text("take,action,style\n" + "".join(f"{t},{t.split('_')[1]},{t.split('_')[2]}\n" for t in TAKES))
  from_csv = read_labels(str(table), sorted(TAKES))
  assert from_csv.fields == ds.labels.fields and from_csv.pattern is None

  with pytest.raises(UserError, match=r"take 'dataset-2_walk' does not match the labels pattern"):
    read_labels(PATTERN, ["dataset-2_walk"])
  with pytest.raises(UserError, match=r"name the labels with groups"):
    read_labels(r"_\d+$", TAKES)
  (tmp_path / "short.csv").write_text("take,action\n" + TAKES[0] + "\n")
  with pytest.raises(UserError, match=r"short.csv:2: expected 2 non-empty cells, got 1"):
    read_labels(str(tmp_path / "short.csv"), TAKES)


def test_a_labelled_run_dances_the_labels_asked_for_from_the_cli_api_and_live(labelled_run, tmp_path, capsys):
  run = load_run(labelled_run)
  assert run.labels is not None and run.num_motions == 4
  np.testing.assert_array_equal(run.motion_weights("action=walk,style=elderly"), [0, 1, 0, 1])
  np.testing.assert_allclose(run.motion_weights(mix="style=elderly:0.5,style=active:0.5"), [0.5, 0.5, 0.5, 0.5])
  np.testing.assert_allclose(run.motion_weights("style=active"), [0.5, 0.5, 1, 0])  # an action not given: even

  out = tmp_path / "walk.npz"
  assert (
    cli.main(["sample", str(labelled_run), "-o", str(out), "--frames", "30", "--motion", "action=walk,style=elderly"])
    == 0
  )
  mixed = tmp_path / "mixed.csv"
  assert (
    cli.main(
      ["sample", str(labelled_run), "-o", str(mixed), "--frames", "30", "--mix", "style=elderly:0.5,style=active:0.5"]
    )
    == 0
  )
  walk = run.sample(frames=30, motion="action=walk,style=elderly")
  assert np.abs(walk.positions - np.load(out)["positions"][0]).max() < 1e-4  # the API draws what the CLI draws
  running = run.sample(frames=30, motion="action=run,style=active")
  assert np.abs(walk.positions - running.positions).max() > 0  # other labels, another dance
  assert json.loads(str(np.load(out)["meta"]))["settings"]["motion"] == "action=walk,style=elderly"

  stream = Stream(run.ranged(run.sampling()), run.sampling(), run.motion_weights("action=run,style=active"), 0, 4)
  stream.next_chunk()
  stream.set(mix="action=walk:1,style=elderly:1")
  np.testing.assert_array_equal(stream.weights, [0, 1, 0, 1])
  with pytest.raises(UserError, match=r"style='sleepy' is not a value this run knows; style: active, elderly"):
    stream.set(mix="style=sleepy:1")

  capsys.readouterr()
  refusals = {
    "action=swim": "--motion: action='swim' is not a value this run knows; action: run, walk",
    "mood=calm": "--motion: no label 'mood'; this run's labels: action, style",
    "3": "--motion 3: this run is conditioned on labels, not take ids: e.g. action=run,style=active",
  }
  for motion, line in refusals.items():
    assert cli.main(["sample", str(labelled_run), "-o", str(tmp_path / "x.csv"), "--motion", motion]) == 2
    assert capsys.readouterr().err.strip() == f"chorjax: error: {line}"
    assert not (tmp_path / "x.csv").exists()


def test_the_governor_holds_each_dancer_to_the_pace_of_its_labels_in_sample_live_and_export(labelled_run, tmp_path):
  """A labelled run keeps the pace of each label pair of its training takes (the judge's measure), and the pace
  governor holds a dancer to its own labels' pace: a run's where it is asked for a run, a walk's for a walk
  (one pace for the whole library held runs to a walk's and waves to a run's)."""
  run = load_run(labelled_run)
  ds = load_dataset(run.config.data)
  f = run.ranged(run.sampling()).features
  table = f.pace_by_label
  assert table.shape == (4, run.num_motions + 1)  # walk and run, elderly and active: trial 002 of each trains
  paces = {}
  for weights, z in ds.train:
    moved = np.concatenate(takes_joint_pace([z], f.pace_lag, f.joint_motion))
    paces[tuple(weights)] = paces.get(tuple(weights), ()) + (moved,)
  for row in table:
    moved = np.concatenate(paces[tuple(row[:-1])])
    np.testing.assert_allclose(np.exp(row[-1]), moved.mean(), rtol=1e-5)

  draw = run.sampling().draw(f)
  pace = lambda motion=None, mix=None: float(draw.for_motion(run.motion_weights(motion, mix)[None]).pacing.ref[0])
  own = {(a, s): float(np.exp(r[-1])) for r in table for a, s in [_pair(run, r[:-1])]}
  for (action, style), expected in own.items():
    assert pace(f"action={action},style={style}") == pytest.approx(expected, rel=1e-5)
  for style in ("elderly", "active"):
    assert own["run", style] > 1.3 * own["walk", style]  # running moves more than walking, in the real takes
  halfway = pace(mix="action=run:0.5,action=walk:0.5,style=active:1")  # a blend: between, in log space
  assert halfway == pytest.approx((own["run", "active"] * own["walk", "active"]) ** 0.5, rel=1e-3)
  assert draw.for_motion(np.array([0])).pacing.ref == f.pace_joints  # take ids: one pace
  # calibration's dancers stand for the takes spread over them, not the first few (a library's sort by label)
  named = [type("Take", (), {"name": n}) for n in run.train_takes]
  expected = [run.take_condition(run.train_takes[k]) for k in (0, 2)]
  np.testing.assert_array_equal(run.dancer_conditions(named, 2), expected)

  # the draw starts each dancer's running pace at its own labels' pace: sample (the API), live and export
  weights = np.stack([run.motion_weights("action=run,style=active"), run.motion_weights("action=walk,style=elderly")])
  start, _ = run.family.stream()
  state = start(run.graphdef, run.params, weights, draw.for_motion(weights))
  np.testing.assert_allclose(state[-1][-1], [own["run", "active"], own["walk", "elderly"]], rtol=1e-5)
  stream = Stream(run.ranged(run.sampling()), run.sampling(), weights[1], 0, 4)
  assert float(stream.state[-1][-1][0]) == pytest.approx(own["walk", "elderly"], rel=1e-5)
  stream.set(mix="action=run:1,style=active:1")
  assert float(stream.state[-1][-1][0]) == pytest.approx(own["run", "active"], rel=1e-5)

  assert cli.main(["export", str(labelled_run), "-o", str(tmp_path / "d.onnx")]) == 0
  frames = 40
  gumbel, normal = sample_numbers(run, 0, frames)
  z = OnnxDancer(tmp_path / "d.onnx").dance(weights[:1], gumbel, normal)
  expected, _ = sample_dancers(run, frames, 1, 0, motion="action=run,style=active")
  got = OnnxDancer(tmp_path / "d.onnx").positions(z)
  assert np.abs(got - expected).max() <= 1e-4 * float(np.ptp(expected.reshape(-1, 3), axis=0).max())


def test_calibration_holds_each_labelled_dancer_to_the_poses_of_its_own_labels(labelled_run, monkeypatch):
  """A labelled run's calibration measures each dancer's poses against its own labels' takes: the real takes,
  each as a dancer under its own labels, are nearer than under another pair's (pooled over the library, the
  labels would not count); a pair with too few takes leaves the pooled distribution in its place."""
  from chorjax.data.transforms import to_y_up
  from chorjax.evaluation.scoring import PoseDistribution
  from chorjax.sampling.calibrate import PosesByLabel

  run = load_run(labelled_run)
  ds = load_dataset(run.config.data)
  motions = sorted(ds.motions, key=lambda m: m.name)
  takes = [np.asarray(to_y_up(m.positions, run.features.up_axis)) for m in motions]
  own = [run.take_condition(m.name) for m in motions]
  sk = run.features.skeleton
  assert PosesByLabel(takes, sk, own, own).groups == []  # two takes per pair: fewer than MIN_TAKES
  assert PosesByLabel(takes, sk, own, own).ratio(takes) == pytest.approx(PoseDistribution(takes, sk).ratio(takes))
  monkeypatch.setattr(PosesByLabel, "MIN_TAKES", 2)
  by_label = PosesByLabel(takes, sk, own, own)
  assert len(by_label.groups) >= 3  # a pair with a take under two windows (75 frames) is left out
  for _, dancers in by_label.groups:  # each pair's two dancers, against its two takes
    assert len(dancers) == 2 and np.array_equal(own[dancers[0]], own[dancers[1]])
  other = [own[(k + 4) % len(own)] for k in range(len(own))]  # run <-> walk, each style kept
  assert [_pair(run, w)[1] for w in other] == [_pair(run, w)[1] for w in own]
  assert [_pair(run, w)[0] for w in other] != [_pair(run, w)[0] for w in own]
  assert 2 * by_label.ratio(takes) < PosesByLabel(takes, sk, own, other).ratio(takes)


def _pair(run, weights_M) -> tuple[str, str]:
  named = [k for k, w in zip(run.id_map, weights_M, strict=True) if w == 1]
  return tuple(k.split("=")[1] for k in named)


def _parses(monkeypatch) -> list:
  """The files parsed from here on (the cache's misses)."""
  import chorjax.data.dataset as dataset

  parsed, read = [], dataset.read_motions
  monkeypatch.setattr(dataset, "read_motions", lambda path, **kw: parsed.append(path.name) or read(path, **kw))
  return parsed


def _same(a, b) -> bool:
  return list(a.id_map) == list(b.id_map) and all(
    np.array_equal(x, y) and np.array_equal(i, j)
    for (i, x), (j, y) in zip(a.train + a.val, b.train + b.val, strict=True)
  )


def test_the_cache_reads_a_changed_take_alone_and_makes_a_damaged_entry_again(takes, tmp_path, monkeypatch, capsys):
  """A library read twice is parsed once; a take whose file changed is the only one read again; an entry
  damaged on disk is made again with one line saying so; what comes out is what reading without it gives."""
  import shutil

  library = tmp_path / "library"
  shutil.copytree(takes, library)
  config = lambda cache: tiny_config(f"data.dataset={library}", f"data.labels={PATTERN}", f"data.cache={cache}").data
  parsed = _parses(monkeypatch)
  first = load_dataset(config(tmp_path / "cache"))
  assert sorted(parsed) == sorted(f"{t}.bvh" for t in TAKES)
  parsed.clear()
  again = load_dataset(config(tmp_path / "cache"))
  assert parsed == [] and _same(first, again)

  changed = library / f"{TAKES[3]}.bvh"  # one number of its last frame moved by a millimetre
  lines = changed.read_text().splitlines()
  numbers = lines[-1].split()
  numbers[0] = f"{float(numbers[0]) + 0.1:.6f}"
  changed.write_text("\n".join([*lines[:-1], " ".join(numbers)]) + "\n")
  third = load_dataset(config(tmp_path / "cache"))
  assert parsed == [changed.name] and not _same(first, third)
  assert _same(third, load_dataset(config("off")))

  entries = sorted((tmp_path / "cache").rglob("*.npz"))
  assert len(entries) == 2 * len(TAKES) + 2  # each file parsed and each take encoded; the changed take twice
  of = lambda entry: json.loads(str(np.load(entry)["meta"]))[0]["name"]
  entries = [e for e in (tmp_path / "cache" / "takes").rglob("*.npz") if of(e) == TAKES[0]]
  entries[0].write_bytes(entries[0].read_bytes()[:100])  # the entry of a parsed file, cut short
  parsed.clear()
  capsys.readouterr()
  fourth = load_dataset(config(tmp_path / "cache"))
  err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("cache:")]
  assert len(err) == 1 and f"cache: {entries[0]} was damaged" in err[0] and err[0].endswith("is read again")
  assert _same(fourth, third) and len(parsed) == 1  # that file alone parsed again
  load_dataset(config(tmp_path / "cache"))
  assert not [line for line in capsys.readouterr().err.splitlines() if line.startswith("cache:")]  # made again


def test_takes_read_and_encoded_in_processes_are_the_ones_read_here(takes, tmp_path, monkeypatch):
  """``data.workers = 2``: two fresh processes parse and encode the takes into the cache, and this process
  reads them back (it parses none): the dataset is the one read in this process alone."""
  config = lambda cache, workers: (
    tiny_config(
      f"data.dataset={takes}", f"data.labels={PATTERN}", f"data.cache={cache}", f"data.workers={workers}"
    ).data
  )
  here = load_dataset(config(tmp_path / "here", 1))
  parsed = _parses(monkeypatch)
  there = load_dataset(config(tmp_path / "there", 2))
  assert parsed == [] and _same(here, there)
  assert len(list((tmp_path / "there").rglob("*.npz"))) == 2 * len(TAKES)


@pytest.mark.parametrize(
  "text, said",
  [
    ("take,action\nt1,walk\nt1,run\n", r"labels.csv:3: take 't1' has another row that says otherwise"),
    ('take,action\nt1,"wa\nlk"\n', r"a label cannot be empty or hold"),
    ("take,action,\nt1,walk,x\n", r"labels.csv:1: field ''"),
    ("take,action,take\nt1,walk,x\n", r"field 'take' is named twice"),
    ("take,action,action\nt1,walk,x\n", r"field 'action' is named twice"),
    ("take,act=ion\nt1,walk\n", r"field 'act=ion'"),
    ("take,action\nt1,wa:lk\n", r"take 't1': action 'wa:lk'"),
    ('take,action\nt1,"a,b"\n', r"take 't1': action 'a,b'"),
  ],
)
def test_a_labels_csv_whose_labels_motion_cannot_name_is_refused(tmp_path, text, said):
  """Conflicting duplicate rows, quoted line breaks, empty or doubled field names, a field named take, and
  fields or values holding , = : were accepted, though ``--motion`` and ``--mix`` could never name them."""
  table = tmp_path / "labels.csv"
  table.write_text(text)
  with pytest.raises(UserError, match=said):
    read_labels(str(table), ["t1"])


def test_a_pattern_reading_a_label_motion_cannot_name_is_refused():
  with pytest.raises(UserError, match=r"take 'a=b_1': x 'a=b'"):
    read_labels(r"^(?P<x>[^_]+)_\d$", ["a=b_1"])
  assert read_labels(r"^(?P<x>[^_]+)_\d$", ["ab_1"]).fields == {"x": ("ab",)}


def test_a_short_take_loops_up_to_data_loop_and_a_held_out_one_too_short_is_left_out(takes):
  """A library's short action, looped: a take shorter than a window is kept, played back to back, so the
  dancer learns to do it again; a held-out take shorter than a window is not validated on."""
  from chorjax.config import load_config

  library = ROOT / "configs" / "library.toml"
  plain = load_dataset(load_config(library, [f"data.dataset={takes}", "data.loop=0"]).data)
  length = {m.name: m.num_frames for m in plain.motions}
  window = sorted(length.values())[len(length) // 2]  # half the takes are shorter than a window
  cfg = load_config(library, [f"data.dataset={takes}", f"data.seq_length={window}", f"data.loop={2 * window / 30}"])
  ds = load_dataset(cfg.data)
  assert min(length[n] for n in plain.train_names) <= window  # without the loop, shorter than one window
  assert ds.fps == 30 and ds.train_names == plain.train_names  # none left out for being short
  units = lambda x, f: x * f.std + f.mean  # the looped takes' statistics differ: compared in the features' units
  for (_, x), (_, raw), name in zip(ds.train, plain.train, ds.train_names):
    n, raw = length[name], units(raw, plain.features)
    assert len(x) == -(-2 * window // n) * n >= 2 * window  # whole plays of the take, at least the loop
    np.testing.assert_allclose(units(x[:n], ds.features), raw, atol=1e-4)
    np.testing.assert_allclose(units(x[n : 2 * n], ds.features), raw, atol=1e-4)
  short = [n for n in plain.val_names if length[n] <= window]
  assert short and ds.val_names == tuple(n for n in plain.val_names if n not in short)
  assert f"note: {len(short)} held-out takes are shorter than one window" in " ".join(dataset_notes(ds))
