"""A job's workdir as the viewer reads it: which job made it, and the decisions it holds.

Three jobs answer "where next?":

| kind              | job                               | a step is                              |
| ----------------- | --------------------------------- | -------------------------------------- |
| `next_views`      | `experiments/next_views.py`      | the proposal: candidates ranked by U   |
| `camera_planning` | `experiments/camera_planning.py`  | one round of one (strategy, seed) run  |
| `light_planning`  | `experiments/light_planning.py`   | one light chosen by one strategy       |

The kind is the job that `config.json` records having written the workdir (`_written_by`,
`mfsample.config_record.WRITTEN_BY`). A `Run` lists its steps (`Step`) from the files the
job writes (re-read on every call, so the rounds, lights and proposals of a running job appear
as they are written; the jobs write every file atomically, so a file not there yet is
skipped until a later call). Cameras and ground-truth images come from the job's own inputs
(its dataset, pool or captures, rebuilt from `config.json` with the library's loaders by
`load_inputs`); without them the viewer shows what the workdir alone holds.

Damage is reported, not fatal: the model of a step is its newest readable checkpoint (the one
the job resumes from, `mfsample.train.checkpoint.newest_readable`), and a file that cannot be
read or holds a malformed record (a `u` that is not a list of numbers, a proposal without a
pose) is named in `Run.problems` while the rest of the run is shown.
"""

import collections
import dataclasses
import glob
import json
import numbers
import os

import ml_collections
import numpy as np

from mfsample.camera import Camera
from mfsample.config_record import WRITTEN_BY
from mfsample.planning import rounds
from mfsample.train import checkpoint as ckpt
from mfsample.viewer import models

KINDS = {
    "next_views": "next views of a capture (experiments/next_views.py)",
    "camera_planning": "camera planning (experiments/camera_planning.py)",
    "light_planning": "light planning (experiments/light_planning.py)",
}
MODELS_KEPT = 4  # models held in memory per run (the steps shown most recently)


class RunError(ValueError):
  """A workdir the viewer cannot show (no run, or a run of an unknown kind)."""


class NoRunYet(RunError):
  """A workdir no job has written to yet (no folder, or no config.json): the viewer can wait
  for it."""


class Malformed(ValueError):
  """A record that does not hold what the job writes (the message says what is wrong)."""


@dataclasses.dataclass(frozen=True)
class Proposal:
  """A proposed next view, in rank order (rank 1 is the job's choice)."""

  rank: int
  name: str
  camera: Camera  # unbatched, numpy leaves
  index: int | None  # into the step's candidates, or None for a pose outside them
  score: float | None


@dataclasses.dataclass(frozen=True)
class Step:
  """One decision of a job, with everything the viewer draws for it.

  Attributes:
    key: unique within the run, stable across polls.
    title: a line for people.
    signature: changes whenever the files behind the step change (the viewer redraws).
    model_path: the `.npz` holding the step's model (`models.read_model`), or None.
    train: the training cameras (`Camera` [V]) and their names, or None.
    candidates: the candidate cameras (`Camera` [C]) and their names, or None.
    scores: [C] the score of each candidate, or None (not yet scored); NaN where the job
      recorded none.
    score_name: what `scores` is ("U" for the uncertainty of Eq. 10).
    proposals: the proposed next views, best first.
    train_images: [V] indices into the run's ground-truth images of the training views
      (`Run.ground_truth("train", ...)` resolves them), or None.
    q: light planning: [n, n] the quadratic form of U over lights for the step's model.
    lights: light planning: ((label, xi [n]), ...) the lights trained on so far.
    next_light: light planning: (label, xi [n]) the light the step chose, or None.
    note: what the workdir does not hold for this step (shown to the user), or "".
  """

  key: str
  title: str
  signature: tuple
  model_path: str | None = None
  train: tuple | None = None
  candidates: tuple | None = None
  scores: np.ndarray | None = None
  score_name: str = "U"
  proposals: tuple = ()
  train_images: tuple | None = None
  q: np.ndarray | None = None
  lights: tuple = ()
  next_light: tuple | None = None
  note: str = ""

  @property
  def coloured(self):
    """Whether the step colours something by a score: its candidates, or the lights."""
    return self.scores is not None or self.q is not None


def default_step(steps):
  """The step a viewer shows first, and while it follows the run: the newest one that colours
  something by a score (scored candidates, U over lights), else the newest; None for none.

  A strategy that scores no candidates (a random choice, an optimised pose) would otherwise
  open the viewer on a scene without colours."""
  if not steps:
    return None
  return next((s for s in reversed(steps) if s.coloured), steps[-1])


# ------------------------------------------------------------------ reading files safely


def _stat(path):
  try:
    st = os.stat(path)
    return (st.st_mtime_ns, st.st_size)
  except OSError:
    return None


def read_json(path):
  """The JSON value in `path`, or None when it is missing or not JSON."""
  try:
    with open(path, encoding="utf-8") as f:
      return json.load(f)
  except (OSError, ValueError):
    return None


def number_list(value, what, length=None):
  """[N] float64 of a JSON list of numbers (null: NaN, as the jobs write a non-finite
  value). Raises `Malformed` naming `what` and the first entry that is not a number."""
  if not isinstance(value, list):
    raise Malformed(f"{what} is {_kind_of(value)}, not a list of numbers")
  for i, v in enumerate(value):
    if v is not None and (isinstance(v, bool) or not isinstance(v, numbers.Real)):
      raise Malformed(f"{what}[{i}] is {v!r}, not a number")
  if length is not None and len(value) != length:
    raise Malformed(f"{what} holds {len(value)} values, not {length}")
  return np.array([np.nan if v is None else float(v) for v in value], np.float64)


def pose_list(value, what):
  """[N, 4, 4] float64 world-to-camera matrices of a JSON list (or one matrix [4, 4]):
  finite and invertible, or `Malformed` naming `what`."""
  try:
    w2c = np.asarray(value, np.float64)
  except (TypeError, ValueError) as e:
    raise Malformed(f"{what} is not a list of 4 x 4 matrices ({e})") from e
  if w2c.ndim == 2:
    w2c = w2c[None]
  if w2c.ndim != 3 or w2c.shape[1:] != (4, 4):
    raise Malformed(f"{what} has shape {w2c.shape}, not [N, 4, 4]")
  if not np.all(np.isfinite(w2c)):
    raise Malformed(f"{what} holds non-finite values")
  if w2c.size and np.min(np.abs(np.linalg.det(w2c[:, :3, :3]))) < 1e-6:
    raise Malformed(f"{what} holds a matrix whose rotation is singular")
  return w2c


def _kind_of(value):
  return {dict: "an object", list: "a list", str: "a string"}.get(type(value), repr(value))


def cameras_from(w2c, fx, fy, cx, cy, width, height) -> Camera:
  """A batched `Camera` with numpy leaves from per-camera arrays (`Malformed` when they do
  not describe cameras: sizes below 1, focal lengths not finite and positive)."""
  w2c = np.asarray(w2c, np.float32).reshape(-1, 4, 4)
  n = len(w2c)
  try:
    full = lambda v: np.broadcast_to(np.asarray(v, np.float32), (n,)).copy()
    fx, fy, cx, cy = full(fx), full(fy), full(cx), full(cy)
    width, height = int(width), int(height)
  except (TypeError, ValueError) as e:
    raise Malformed(f"intrinsics that are not numbers for {n} cameras ({e})") from e
  if width < 1 or height < 1:
    raise Malformed(f"an image size of {width} x {height}")
  if not (np.all(np.isfinite([fx, fy, cx, cy])) and np.all(fx > 0) and np.all(fy > 0)):
    raise Malformed("focal lengths or centres that are not finite, or focal lengths <= 0")
  return Camera(w2c, fx, fy, cx, cy, width, height)


def numpy_cameras(cameras) -> Camera:
  """`cameras` with numpy leaves (cheap to index on the host)."""
  return Camera(np.asarray(cameras.world_to_camera, np.float32), np.asarray(cameras.fx),
                np.asarray(cameras.fy), np.asarray(cameras.cx), np.asarray(cameras.cy),
                cameras.width, cameras.height)


def with_poses(reference: Camera, w2c) -> Camera:
  """Cameras at the poses `w2c` [N, 4, 4] with the intrinsics of `reference[0]`."""
  ref = reference[0] if reference.batch_shape else reference
  return cameras_from(w2c, ref.fx, ref.fy, ref.cx, ref.cy, ref.width, ref.height)


def _index(value, count, what):
  """`value` as an index into `count` items (None stays None), or `Malformed`."""
  if value is None:
    return None
  if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not (
      0 <= value < count):
    raise Malformed(f"{what} is {value!r}, not an index of the {count} candidates")
  return int(value)


# ------------------------------------------------------------------ the kinds of run


def run_kind(config):
  """The kind of job (a key of `KINDS`) that wrote the config dict `config` (its
  `_written_by` record), or None when it records none."""
  record = config.get(WRITTEN_BY) if isinstance(config, dict) else None
  return record.get("job") if isinstance(record, dict) else None


def open_run(workdir):
  """The `Run` of the job that wrote `workdir`.

  Raises:
    NoRunYet: no such folder, or no `config.json` in it (no job has started there yet).
    RunError: a `config.json` that cannot be read, or a run of another kind.
  """
  workdir = os.fspath(workdir)
  if not os.path.isdir(workdir):
    raise NoRunYet(f"--workdir={workdir}: no such folder")
  path = os.path.join(workdir, "config.json")
  if not os.path.exists(path):
    raise NoRunYet(f"{workdir} holds no run: no config.json (the first file a job writes). "
                   f"The viewer shows the workdirs of {_kinds_sentence()}.")
  config = read_json(path)
  if not isinstance(config, dict):
    raise RunError(f"{path} is not a JSON object: the run in {workdir} cannot be read")
  kind = run_kind(config)
  if kind is None:
    raise RunError(f"{path} does not record which job wrote {workdir} (no "
                   f"{WRITTEN_BY!r}: a workdir of mfsample before 0.2); the viewer shows "
                   f"the workdirs of {_kinds_sentence()}")
  if kind not in KINDS:
    raise RunError(f"{workdir} holds a run of the {kind!r} job, which the viewer does not "
                   f"show; it shows the workdirs of {_kinds_sentence()}")
  return {"next_views": NextViewsRun, "camera_planning": CameraPlanningRun,
          "light_planning": LightPlanningRun}[kind](workdir, config)


def _kinds_sentence():
  return ", ".join(KINDS.values())


class Run:
  """A workdir of one kind: its steps (`Step`), its inputs and its models.

  Attributes:
    kind: a key of `KINDS`.
    workdir: the folder.
    config: the job's config (`ml_collections.ConfigDict` of `config.json`).
    inputs_error: why the job's inputs could not be rebuilt ("" when they were, or not yet
      tried).
    problems: the damaged files of the last `steps()` and model reads, one line each naming
      the file (relative to the workdir) and what is wrong with it.
  """

  kind = ""

  def __init__(self, workdir, config_dict):
    self.workdir = workdir
    self.config = ml_collections.ConfigDict(
        {k: v for k, v in config_dict.items() if k != WRITTEN_BY})
    self.written_by = dict(config_dict.get(WRITTEN_BY, {}))
    self.inputs = None
    self.inputs_error = ""
    self._models = collections.OrderedDict()  # (path, stat) -> Model, the newest last
    self._unreadable = {}  # (path, stat) -> why the file holds no model
    self._metas = {}  # (path, stat) -> metadata dict, or the error reading it
    self._problems = {}  # of the current steps(): path -> line
    self._model_problems = {}  # path -> line, from model reads since

  # ---------------------------------------------------------------- damage

  def rel(self, text):
    """`text` with the workdir's path left out of the file names it holds."""
    return str(text).replace(os.path.join(self.workdir, ""), "")

  def problem(self, path, message, named=False):
    """Records that the file `path` is damaged (`message`: what is wrong, what is shown;
    `named`: the message already names the file)."""
    line = self.rel(message) if named else f"{self.rel(path)}: {self.rel(message)}"
    self._problems[path] = line

  @property
  def problems(self):
    lines = dict(self._problems)
    lines.update(self._model_problems)
    return tuple(lines.values())

  def path(self, *parts):
    return os.path.join(self.workdir, *parts)

  def read_record(self, path):
    """The JSON object in `path`: None when the file is missing, or when it is not a JSON
    object (then a problem names it)."""
    try:
      with open(path, encoding="utf-8") as f:
        value = json.load(f)
    except FileNotFoundError:
      return None
    except (OSError, ValueError) as e:
      self.problem(path, f"unreadable or not JSON ({type(e).__name__}: {e}); ignored")
      return None
    if not isinstance(value, dict):
      self.problem(path, f"holds {_kind_of(value)} where the job writes a JSON object; "
                         "ignored")
      return None
    return value

  def read_meta(self, path):
    """The metadata of a checkpoint or round file, read again only when the file changed (a
    poll of an unchanged workdir opens no archive); None, with a problem naming the file,
    when it cannot be read."""
    key = (path, _stat(path))
    if key not in self._metas:
      self._metas = {k: v for k, v in self._metas.items() if k[0] != path}
      try:
        self._metas[key] = ckpt.read_meta(path)
      except ckpt.CorruptCheckpointError as e:
        self._metas[key] = e
    meta = self._metas[key]
    if isinstance(meta, Exception):
      self.problem(path, f"{meta}; not shown", named=True)
      return None
    return meta

  def _model_at(self, path):
    """The `Model` in `path`, read once per file version (the last `MODELS_KEPT` kept).

    Raises:
      ckpt.CorruptCheckpointError: the file cannot be read, or holds no model.
    """
    key = (path, _stat(path))
    if key in self._models:
      self._models.move_to_end(key)
      return self._models[key]
    if key not in self._unreadable:
      try:
        model = models.read_model(path)
      except (ckpt.CorruptCheckpointError, models.ModelFileError) as e:
        self._unreadable = {k: v for k, v in self._unreadable.items() if k[0] != path}
        self._unreadable[key] = str(e)
      else:
        self._models[key] = model
        while len(self._models) > MODELS_KEPT:
          self._models.popitem(last=False)
        return model
    raise ckpt.CorruptCheckpointError(self._unreadable[key])

  def newest_model(self, directory):
    """(path, note) of the newest checkpoint in `directory` that holds a readable model:
    the one the job resumes from. The newer ones that cannot be read are problems, and the
    note says which one is shown instead; (None, note) when none can be read."""
    path, _, skipped = ckpt.newest_readable(directory, self._model_at)
    for bad, e in skipped:
      self.problem(bad, f"{e}; passed over" if path else str(e), named=True)
    if not skipped:
      return path, ""
    newest = self.rel(ckpt.list_checkpoints(directory)[-1])
    if path is None:
      return None, f"no checkpoint in {self.rel(directory)} can be read: no model to draw"
    return path, (f"{newest} cannot be read: showing {self.rel(path)}, the checkpoint the "
                  "job resumes from")

  def model(self, step):
    """The `Model` of `step`, or None (none, or its file cannot be read: a problem then
    names it)."""
    if step.model_path is None:
      return None
    try:
      model = self._model_at(step.model_path)
    except ckpt.CorruptCheckpointError as e:
      self._model_problems[step.model_path] = f"{self.rel(e)}; no model drawn"
      return None
    self._model_problems.pop(step.model_path, None)
    return model

  # ---------------------------------------------------------------- inputs and steps

  def load_inputs(self):
    """Rebuilds the job's cameras and images from `config.json` (once). On failure the
    reason is kept in `inputs_error` and the viewer goes on without them."""
    if self.inputs is not None or self.inputs_error:
      return
    try:
      self.inputs = self._load_inputs()
    except Exception as e:  # noqa: BLE001 - any loader failure: show what the workdir holds
      self.inputs_error = (f"the job's inputs could not be rebuilt from config.json "
                           f"({type(e).__name__}: {e}); showing what the workdir holds")

  def _load_inputs(self):
    raise NotImplementedError

  def steps(self):
    """The run's steps (`Step`) in the order the job made them (re-read from the files); the
    damaged files met are in `problems`."""
    self._problems = {}
    self._model_problems = {p: line for p, line in self._model_problems.items()
                            if os.path.exists(p)}
    return self._read_steps()

  def _read_steps(self):
    raise NotImplementedError

  def u_samples(self):
    """(M, Sobol seed) of the job's U."""
    raise NotImplementedError

  def background(self):
    return tuple(float(c) for c in self.config.data.get("background", (0.0, 0.0, 0.0)))

  def score_downscale(self):
    """The factor by which the job shrinks the candidates' images to score them."""
    return 1

  def light_of(self, step):
    """The SH light [n] of the step's renders (light planning), or None."""
    return None

  def ground_truth(self, step, group, index):
    """[H, W, 3] the image the job holds for camera `index` of `group` ("train" or
    "candidates") of `step`, or None."""
    return None


# ------------------------------------------------------------------ next views


class NextViewsRun(Run):
  """The your-data job (`mfsample.your_data`): train or fit, then rank the candidates."""

  kind = "next_views"

  def _load_inputs(self):
    from mfsample.config_blocks import data_spec
    from mfsample.data import load_dataset
    from mfsample.your_data.candidates import sphere_candidates

    dataset = load_dataset(data_spec(self.config.data))
    every = int(self.config.views.train_every)
    index = np.arange(len(dataset.train))
    train_idx, unused_idx = index[index % every == 0], index[index % every != 0]
    names = list(dataset.train.names) if dataset.train.names else [
        f"train_{i}" for i in index]
    cams = numpy_cameras(dataset.train.cameras)
    images = np.asarray(dataset.train.images)
    out = {"train": (cams[train_idx], [names[i] for i in train_idx]),
           "train_images": images[train_idx]}
    if self.config.next_views.candidates == "unused":
      out["candidates"] = (cams[unused_idx], [names[i] for i in unused_idx])
      out["candidate_images"] = images[unused_idx]
    else:
      center = 0.5 * (np.asarray(dataset.bounds[0], np.float64)
                      + np.asarray(dataset.bounds[1], np.float64))
      sphere = sphere_candidates(cams[train_idx], center,
                                 int(self.config.next_views.sphere_views))
      out["candidates"] = (numpy_cameras(sphere),
                           [f"sphere_{i:03d}" for i in range(len(sphere))])
      out["candidate_images"] = None
    return out

  def u_samples(self):
    return int(self.config.next_views.samples), int(self.config.next_views.z_seed)

  def score_downscale(self):
    return int(self.config.next_views.score_downscale)

  def _read_steps(self):
    latest, model_note = self.newest_model(self.path("checkpoints"))
    record_path, results_path = self.path("next_views.json"), self.path("results.json")
    record = self.read_record(record_path)
    inputs = self.inputs or {}
    candidates = inputs.get("candidates")
    signature = (latest, _stat(latest) if latest else None, _stat(record_path),
                 _stat(results_path), candidates is not None)
    notes = [n for n in (self.inputs_error, model_note) if n]
    scores, proposals = None, ()
    if record is not None:
      count = None if candidates is None else len(candidates[1])
      try:
        scores = number_list(record.get("u"), "u", count)
      except Malformed as e:
        self.problem(record_path, f"{e}: the candidates are shown unscored")
      proposals = self._proposals(record_path, record, count)
      steps_done = self._steps_done(results_path)
      count = count if count is not None else (None if scores is None else len(scores))
      title = (f"next {len(proposals)} of {count} candidates" if count is not None
               else f"next {len(proposals)} views")
      if steps_done is not None:
        title += f" · model after {steps_done} steps"
    else:
      meta = self.read_meta(latest) if latest else None
      title = (f"training: step {meta['step']}" if meta else "training not started")
      title += " (no proposal yet)"
    if latest is None and not model_note:
      notes.append("no checkpoint in checkpoints/: no model to draw")
    return [Step(key="proposal", title=title, signature=signature, model_path=latest,
                 train=inputs.get("train"), candidates=candidates, scores=scores,
                 proposals=proposals,
                 train_images=tuple(range(len(inputs["train"][1]))) if "train" in inputs
                 else None, note="; ".join(notes))]

  def _proposals(self, path, record, count):
    """The `Proposal`s of next_views.json's `top_k`; a malformed entry is a problem and is
    not drawn."""
    top_k = record.get("top_k", [])
    if not isinstance(top_k, list):
      self.problem(path, f"top_k is {_kind_of(top_k)}, not a list: no proposal drawn")
      return ()
    out, bad = [], []
    for i, entry in enumerate(top_k):
      try:
        out.append(_next_view_proposal(entry, i, count))
      except Malformed as e:
        bad.append(str(e))
    if bad:
      self.problem(path, "; ".join(bad) + " (not drawn)")
    return tuple(out)

  def ground_truth(self, step, group, index):
    if not self.inputs:
      return None
    images = self.inputs["train_images" if group == "train" else "candidate_images"]
    return None if images is None else images[int(index)]

  def _steps_done(self, path):
    results = self.read_record(path)
    steps = None if results is None else results.get("steps")
    if steps is None or (isinstance(steps, numbers.Integral) and not isinstance(steps, bool)):
      return steps
    self.problem(path, f"steps is {steps!r}, not a number of steps; ignored")
    return None


def _next_view_proposal(entry, i, count):
  """The `Proposal` of entry `i` of next_views.json's `top_k` (`Malformed` naming it)."""
  what = f"top_k[{i}]"
  if not isinstance(entry, dict):
    raise Malformed(f"{what} is {_kind_of(entry)}, not an object")
  try:
    k = entry["intrinsics"]
    w2c = pose_list(entry["world_to_camera"], f"{what}.world_to_camera")
    if len(w2c) != 1:
      raise Malformed(f"{what}.world_to_camera holds {len(w2c)} poses, not one")
    camera = cameras_from(w2c, k["fx"], k["fy"], k["cx"], k["cy"], k["width"], k["height"])[0]
    rank = entry.get("rank", i + 1)
    if isinstance(rank, bool) or not isinstance(rank, numbers.Integral):
      raise Malformed(f"{what}.rank is {rank!r}")
    score = entry.get("u")
    if score is not None and (isinstance(score, bool) or not isinstance(score, numbers.Real)):
      raise Malformed(f"{what}.u is {score!r}, not a number")
    index = entry.get("index")
    if count is not None:
      index = _index(index, count, f"{what}.index")
    elif index is not None and (isinstance(index, bool) or
                                not isinstance(index, numbers.Integral)):
      raise Malformed(f"{what}.index is {index!r}")
    return Proposal(int(rank), str(entry.get("name", "")), camera, index,
                    None if score is None else float(score))
  except (KeyError, TypeError) as e:
    raise Malformed(f"{what} lacks {e}" if isinstance(e, KeyError)
                    else f"{what} is malformed ({e})") from e
  except Malformed as e:
    raise Malformed(str(e) if str(e).startswith(what) else f"{what}: {e}") from e


# ------------------------------------------------------------------ camera planning


class CameraPlanningRun(Run):
  """The camera-planning protocol (`mfsample.planning`): rounds of (strategy, seed) runs."""

  kind = "camera_planning"

  def _load_inputs(self):
    from mfsample.config_blocks import data_spec
    from mfsample.planning.pool import make_pool

    pool = make_pool(data_spec(self.config.data))
    return {"candidates": numpy_cameras(pool.candidates.cameras),
            "candidate_images": np.asarray(pool.candidates.images),
            "names": list(pool.candidates.names) if pool.candidates.names else None}

  def u_samples(self):
    ours = self.config.strategy.ours
    return int(ours.select_samples), int(ours.z_seed)

  def score_downscale(self):
    return int(self.config.strategy.ours.score_downscale)

  def _candidates(self):
    """(`Camera` [C], names) of the pool: from rounds/candidates.npz, else the inputs."""
    path = self.path(rounds.DIRECTORY, rounds.CANDIDATES)
    cams = None
    if os.path.exists(path):
      try:
        with np.load(path, allow_pickle=False) as data:
          w2c = pose_list(data["world_to_camera"], "world_to_camera")
          cams = cameras_from(w2c, data["fx"], data["fy"], data["cx"], data["cy"],
                              data["width"], data["height"])
      except (*ckpt.READ_ERRORS, Malformed) as e:
        self.problem(path, f"unreadable ({type(e).__name__}: {e}); "
                           + ("the pool's cameras are rebuilt from config.json instead"
                              if self.inputs else "the pool's cameras are unknown"))
    if cams is None and self.inputs:
      cams = self.inputs["candidates"]
    if cams is None:
      return None
    names = (self.inputs or {}).get("names")
    if not names or len(names) != len(cams):
      names = [f"candidate_{i:03d}" for i in range(len(cams))]
    return cams, list(names)

  def _read_steps(self):
    candidates = self._candidates()
    out = {}
    for directory in sorted(glob.glob(self.path(rounds.DIRECTORY, "*-seed*"))):
      for path in ckpt.list_checkpoints(directory):
        meta = self.read_meta(path)
        if meta is not None:
          try:
            step = self._round_step(path, meta, candidates)
          except (Malformed, KeyError, TypeError, ValueError) as e:
            self.problem(path, f"its round record is malformed ({_reason(e)}); not shown")
            continue
          out[step.key] = step
    for path in sorted(glob.glob(self.path("runs", "*.json"))):
      record = self.read_record(path)
      if record is not None:
        try:
          steps = self._record_steps(path, record, candidates)
        except (Malformed, KeyError, TypeError, ValueError) as e:
          self.problem(path, f"the run's record is malformed ({_reason(e)}); not shown")
          continue
        for step in steps:
          out.setdefault(step.key, step)  # a round file says more than the record
    order = {name: i for i, name in enumerate(self.config.strategies)}
    return sorted(out.values(), key=lambda s: (s.signature[0], order.get(s.signature[1], 99),
                                               s.signature[2]))

  def _names(self, candidates, indices):
    names = candidates[1] if candidates else None
    return [names[i] if (names and i is not None) else "new pose" for i in indices]

  def _round_step(self, path, meta, candidates):
    views = meta["step"]
    seed, name = int(meta["seed"]), str(meta["strategy"])
    chosen = meta["chosen"]
    if not isinstance(chosen, dict):
      raise Malformed(f"chosen is {_kind_of(chosen)}")
    count = None if candidates is None else len(candidates[1])
    train_w2c = pose_list(meta["train_world_to_camera"], "train_world_to_camera")
    train_idx = meta["train"]
    if not isinstance(train_idx, list) or len(train_idx) != len(train_w2c):
      raise Malformed(f"train is {train_idx!r}, not one index per training pose")
    scores = meta.get("scores")
    notes = [self.inputs_error] if self.inputs_error else []
    if scores is not None:
      try:
        scores = number_list(scores, "scores", count)
      except Malformed as e:
        self.problem(path, f"{e}: the candidates are shown unscored")
        scores = None
    train = proposals = None
    if candidates is not None:
      train_idx = [_index(i, count, f"train[{j}]") for j, i in enumerate(train_idx)]
      index = _index(chosen.get("index"), count, "chosen.index")
      camera = with_poses(candidates[0], pose_list(chosen["world_to_camera"],
                                               "chosen.world_to_camera"))[0]
      train = (with_poses(candidates[0], train_w2c), self._names(candidates, train_idx))
      score = chosen.get("score")
      proposals = (Proposal(1, self._names(candidates, [index])[0], camera, index,
                            None if score is None else float(score)),)
    else:
      notes.append("the pool's cameras are unknown (no rounds/candidates.npz)")
    if meta.get("model") is None:
      notes.append("the round model is kept for the first seed only" if
                   int(seed) != int(self.config.seeds[0]) else "this strategy trains no model")
    score_name = "U" if name.startswith("ours") else f"{meta.get('label', name)} score"
    return Step(
        key=f"{name}-seed{seed}/{views}",
        title=_round_title(meta.get("label", name), seed, views),
        signature=(seed, name, views, _stat(path), candidates is not None),
        model_path=path if meta.get("model") else None, train=train,
        candidates=candidates, scores=scores, score_name=score_name,
        proposals=proposals or (), train_images=tuple(train_idx), note="; ".join(notes))

  def _record_steps(self, path, record, candidates):
    name, seed = str(record["strategy"]), int(record["seed"])
    indices = record["indices"]
    w2c = pose_list(record["world_to_camera"], "world_to_camera")
    scores = number_list(record["scores"], "scores")
    if not isinstance(indices, list) or not len(indices) == len(w2c) == len(scores):
      raise Malformed("indices, world_to_camera and scores differ in length")
    count = None if candidates is None else len(candidates[1])
    if count is not None:
      indices = [_index(i, count, f"indices[{j}]") for j, i in enumerate(indices)]
    out = []
    for views in range(1, len(indices)):
      train = proposals = None
      if candidates is not None:
        train = (with_poses(candidates[0], w2c[:views]),
                 self._names(candidates, indices[:views]))
        camera = with_poses(candidates[0], w2c[views:views + 1])[0]
        proposals = (Proposal(1, self._names(candidates, [indices[views]])[0], camera,
                              indices[views], float(scores[views])),)
      out.append(Step(
          key=f"{name}-seed{seed}/{views}",
          title=_round_title(record.get("label", name), seed, views),
          signature=(seed, name, views, _stat(path), candidates is not None), train=train,
          candidates=candidates, proposals=proposals or (), train_images=tuple(indices[:views]),
          note="from the finished run's record: no round model or candidate scores"))
    return out

  def ground_truth(self, step, group, index):
    if not self.inputs:
      return None
    if group == "train":
      index = step.train_images[int(index)] if step.train_images else None
    return None if index is None else self.inputs["candidate_images"][int(index)]


def _reason(e):
  return str(e) if isinstance(e, Malformed) else f"{type(e).__name__}: {e}"


def _round_title(label, seed, views):
  return f"{label}, seed {seed}: view {views + 1} chosen on {views} view{'s' * (views > 1)}"


# ------------------------------------------------------------------ light planning


class LightPlanningRun(Run):
  """The light-planning protocol (`mfsample.lighting`): lights chosen phase by phase."""

  kind = "light_planning"

  def _load_inputs(self):
    from mfsample.config_blocks import data_spec
    from mfsample.data.datasets import load_light_data

    data = load_light_data(data_spec(self.config.data), int(self.config.model.light_coeffs))
    return {"train": (numpy_cameras(data.train_cameras),
                      [f"camera_{i:02d}" for i in range(len(data.train_cameras))]),
            "basis": data.train_basis}

  def u_samples(self):
    return int(self.config.planning.samples), int(self.config.planning.z_seed)

  def background(self):
    return (0.0, 0.0, 0.0)  # the oracle's SH captures: radiance 0 behind the scene

  def _read_steps(self):
    from mfsample.lighting import strategies
    from mfsample.lighting.lights import uniform_light

    n = int(self.config.model.light_coeffs)
    uniform = ("uniform light", uniform_light(n))
    inputs = self.inputs or {}
    notes = [self.inputs_error] if self.inputs_error else []
    shared_model, shared_note = self.newest_model(self.path("shared"))
    shared_path = self.path("shared", "record.json")
    shared = self.read_record(shared_path)
    out = []
    base = dict(train=inputs.get("train"),
                train_images=tuple(range(len(inputs["train"][1]))) if "train" in inputs
                else None)
    if shared is not None:
      try:
        q = _quadratic_form(shared.get("q"), n, "q")
      except Malformed as e:
        self.problem(shared_path, f"{e}; the first phase is not shown")
      else:
        out.append(Step(key="shared", title="first phase: the uniform light",
                        signature=(_stat(shared_path), _stat(shared_model) if shared_model
                                   else None, bool(inputs)),
                        model_path=shared_model, q=q, lights=(uniform,),
                        note="; ".join(notes + ([shared_note] if shared_note else [])),
                        **base))
    total = int(self.config.num_lights)
    for name in self.config.strategies:
      label = strategies.STRATEGIES[name].label if name in strategies.STRATEGIES else name
      done_path = self.path("runs", f"{name}.json")
      record = self.read_record(done_path)
      running, running_note = self.newest_model(self.path("runs", name))
      running_meta = self.read_meta(running) if running else None
      if record is not None:
        phases, source = record.get("phases"), done_path
      elif running_meta is not None:
        phases, source = running_meta.get("phases"), running
        phases = [p for p in phases[1:] if p] if isinstance(phases, list) else phases
      else:
        continue
      if not isinstance(phases, list):
        self.problem(source, f"phases is {_kind_of(phases)}, not a list; not shown")
        continue
      used = [uniform]
      for i, phase in enumerate(phases):
        try:
          if not isinstance(phase, dict):
            raise Malformed(f"phases[{i}] is {_kind_of(phase)}")
          lights_now = phase["lights"]
          if isinstance(lights_now, bool) or not isinstance(lights_now, numbers.Integral):
            raise Malformed(f"phases[{i}].lights is {lights_now!r}")
          xi = number_list(phase["light"], f"phases[{i}].light", n)
          q = _quadratic_form(phase["q"], n, f"phases[{i}].q")
        except (Malformed, KeyError) as e:
          self.problem(source, f"{_reason(e)}; the lights from there on are not shown")
          break
        model = shared_model if lights_now == 2 else None
        note = "" if model else ("the job keeps the model of the first phase and of a "
                                 "running strategy's latest phase only")
        chosen = (f"light {lights_now} ({label})", xi)
        out.append(Step(key=f"{name}/{lights_now}",
                        title=f"{label}: light {lights_now} of {total}",
                        signature=(_stat(source), bool(inputs), model), model_path=model,
                        q=q, lights=tuple(used), next_light=chosen,
                        note="; ".join(notes + ([note] if note else [])), **base))
        used.append(chosen)
      if record is None and running_meta is not None:
        out.append(Step(key=f"{name}/trained{len(used)}",
                        title=f"{label}: trained on {len(used)} lights (running)",
                        signature=(_stat(running), bool(inputs)), model_path=running,
                        lights=tuple(used),
                        note="; ".join(notes + [n for n in (running_note,) if n] + [
                            "U over lights of this model is computed when the next light "
                            "is chosen"]), **base))
    return out

  def light_of(self, step):
    """The light a step's renders use: the one it chose, else the last trained on."""
    if step.next_light is not None:
      return step.next_light[1]
    return step.lights[-1][1] if step.lights else None

  def ground_truth(self, step, group, index):
    from mfsample.lighting.captures import capture

    if not self.inputs or group != "train":
      return None
    xi = self.light_of(step)
    return np.clip(capture(self.inputs["basis"][int(index):int(index) + 1], xi)[0], 0.0, 1.0)


def _quadratic_form(value, n, what):
  """[n, n] float64 of a JSON matrix (`Malformed` naming `what` otherwise)."""
  if not isinstance(value, list):
    raise Malformed(f"{what} is {_kind_of(value)}, not an {n} x {n} matrix")
  rows = [number_list(row, f"{what}[{i}]", n) for i, row in enumerate(value)]
  if len(rows) != n:
    raise Malformed(f"{what} has {len(rows)} rows, not {n}")
  q = np.stack(rows)
  if not np.all(np.isfinite(q)):
    raise Malformed(f"{what} holds non-finite values")
  return q
