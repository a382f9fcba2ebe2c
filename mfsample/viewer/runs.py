"""A job's workdir as the viewer reads it: which job made it, and the decisions it holds.

Three jobs answer "where next?":

| kind              | job                               | a step is                              |
| ----------------- | --------------------------------- | -------------------------------------- |
| `next_views`      | `experiments/next_views.py`      | the proposal: candidates ranked by U   |
| `camera_planning` | `experiments/camera_planning.py`  | one round of one (strategy, seed) run  |
| `light_planning`  | `experiments/light_planning.py`   | one light chosen by one strategy       |

The kind is the job that `config.json` records having written the workdir (`_written_by`,
`mfsample.config_record.WRITTEN_BY`). A `Run` lists its steps (`Step`) from
the files the job writes (re-read on every call, so the rounds, lights and proposals of a
running job appear as they are written); a file that is missing, partial or being replaced
is skipped until a later call. Cameras and ground-truth images come from the job's own
inputs (its dataset, pool or captures, rebuilt from `config.json` with the library's loaders
by `load_inputs`); without them the viewer shows what the workdir alone holds.
"""

import dataclasses
import glob
import json
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


class RunError(ValueError):
  """A workdir the viewer cannot show (no run, or a run of an unknown kind)."""


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
    scores: [C] the score of each candidate, or None (not yet scored).
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


# ------------------------------------------------------------------ reading files safely


def _stat(path):
  try:
    st = os.stat(path)
    return (st.st_mtime_ns, st.st_size)
  except OSError:
    return None


def read_json(path):
  """The JSON value in `path`, or None when it is missing or not (yet) whole."""
  try:
    with open(path, encoding="utf-8") as f:
      return json.load(f)
  except (OSError, ValueError):
    return None


def cameras_from(w2c, fx, fy, cx, cy, width, height) -> Camera:
  """A batched `Camera` with numpy leaves from per-camera arrays."""
  w2c = np.asarray(w2c, np.float32).reshape(-1, 4, 4)
  n = len(w2c)
  full = lambda v: np.broadcast_to(np.asarray(v, np.float32), (n,)).copy()
  return Camera(w2c, full(fx), full(fy), full(cx), full(cy), int(width), int(height))


def numpy_cameras(cameras) -> Camera:
  """`cameras` with numpy leaves (cheap to index on the host)."""
  return Camera(np.asarray(cameras.world_to_camera, np.float32), np.asarray(cameras.fx),
                np.asarray(cameras.fy), np.asarray(cameras.cx), np.asarray(cameras.cy),
                cameras.width, cameras.height)


def with_poses(reference: Camera, w2c) -> Camera:
  """Cameras at the poses `w2c` [N, 4, 4] with the intrinsics of `reference[0]`."""
  ref = reference[0] if reference.batch_shape else reference
  return cameras_from(w2c, ref.fx, ref.fy, ref.cx, ref.cy, ref.width, ref.height)


# ------------------------------------------------------------------ the kinds of run


def run_kind(config):
  """The kind of job (a key of `KINDS`) that wrote the config dict `config` (its
  `_written_by` record), or None when it records none."""
  record = config.get(WRITTEN_BY) if isinstance(config, dict) else None
  return record.get("job") if isinstance(record, dict) else None


def open_run(workdir):
  """The `Run` of the job that wrote `workdir`.

  Raises:
    RunError: no such folder, no run in it (no `config.json`), or a run of another kind.
  """
  workdir = os.fspath(workdir)
  if not os.path.isdir(workdir):
    raise RunError(f"--workdir={workdir}: no such folder")
  path = os.path.join(workdir, "config.json")
  if not os.path.exists(path):
    raise RunError(f"{workdir} holds no run: no config.json (the first file a job writes). "
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
  """

  kind = ""

  def __init__(self, workdir, config_dict):
    self.workdir = workdir
    self.config = ml_collections.ConfigDict(
        {k: v for k, v in config_dict.items() if k != WRITTEN_BY})
    self.written_by = dict(config_dict.get(WRITTEN_BY, {}))
    self.inputs = None
    self.inputs_error = ""
    self._models = {}
    self._metas = {}

  def path(self, *parts):
    return os.path.join(self.workdir, *parts)

  def read_meta(self, path):
    """The metadata of a checkpoint or round file (`models.read_meta`), read again only when
    the file changed: a poll of an unchanged workdir opens no archive."""
    key = (path, _stat(path))
    if key not in self._metas:
      self._metas = {k: v for k, v in self._metas.items() if k[0] != path}
      self._metas[key] = models.read_meta(path)
    return self._metas[key]

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
    """The run's steps (`Step`) in the order the job made them (re-read from the files)."""
    raise NotImplementedError

  def model(self, step):
    """The `Model` of `step`, or None (read once per file version)."""
    if step.model_path is None:
      return None
    stat = _stat(step.model_path)
    key = (step.model_path, stat)
    if key not in self._models:
      try:
        self._models = {key: models.read_model(step.model_path)}
      except models.ModelFileError:
        return None  # replaced while read: the next poll reads the new file
    return self._models[key]

  def u_samples(self):
    """(M, Sobol seed) of the job's U."""
    raise NotImplementedError

  def background(self):
    return tuple(float(c) for c in self.config.data.get("background", (0.0, 0.0, 0.0)))

  def score_downscale(self):
    """The factor by which the job shrinks the candidates' images to score them."""
    return 1

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

  def steps(self):
    checkpoints = ckpt.list_checkpoints(self.path("checkpoints"))
    latest = checkpoints[-1] if checkpoints else None
    record_path = self.path("next_views.json")
    record = read_json(record_path)
    inputs = self.inputs or {}
    candidates = inputs.get("candidates")
    signature = (latest, _stat(latest) if latest else None, _stat(record_path),
                 candidates is not None)
    notes = [self.inputs_error] if self.inputs_error else []
    scores, proposals = None, ()
    if isinstance(record, dict) and isinstance(record.get("u"), list):
      scores = np.asarray(record["u"], np.float64)
      if candidates is not None and len(scores) != len(candidates[1]):
        notes.append(f"next_views.json scores {len(scores)} candidates, the config gives "
                     f"{len(candidates[1])}: candidates shown unscored")
        scores = None
      proposals = tuple(_next_view_proposal(t) for t in record.get("top_k", [])
                        if _next_view_proposal(t) is not None)
      steps_done = (read_json(self.path("results.json")) or {}).get("steps")
      title = (f"next {len(proposals)} of {len(record['u'])} candidates"
               + (f" (model after {steps_done} steps)" if steps_done else ""))
    else:
      meta = self.read_meta(latest) if latest else None
      title = ("training: step " + str(meta["step"]) if meta else "training not started")
      title += " (no proposal yet)"
    if latest is None:
      notes.append("no checkpoint in checkpoints/: no model to draw")
    return [Step(key="proposal", title=title, signature=signature, model_path=latest,
                 train=inputs.get("train"), candidates=candidates, scores=scores,
                 proposals=proposals,
                 train_images=tuple(range(len(inputs["train"][1]))) if "train" in inputs
                 else None, note="; ".join(notes))]

  def ground_truth(self, step, group, index):
    if not self.inputs:
      return None
    images = self.inputs["train_images" if group == "train" else "candidate_images"]
    return None if images is None else images[int(index)]


def _next_view_proposal(entry):
  """A `Proposal` of one `top_k` entry of next_views.json, or None if it is malformed."""
  try:
    k = entry["intrinsics"]
    camera = cameras_from(entry["world_to_camera"], k["fx"], k["fy"], k["cx"], k["cy"],
                          k["width"], k["height"])[0]
    return Proposal(int(entry["rank"]), str(entry["name"]), camera, int(entry["index"]),
                    float(entry["u"]))
  except (KeyError, TypeError, ValueError, IndexError):
    return None


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
    try:
      with np.load(path) as data:
        cams = cameras_from(data["world_to_camera"], data["fx"], data["fy"], data["cx"],
                            data["cy"], int(data["width"]), int(data["height"]))
    except (OSError, ValueError, KeyError, EOFError):
      if self.inputs:
        cams = self.inputs["candidates"]
    if cams is None:
      return None
    names = (self.inputs or {}).get("names") or [f"candidate_{i:03d}" for i in range(len(cams))]
    return cams, list(names)

  def steps(self):
    candidates = self._candidates()
    out = {}
    for directory in sorted(glob.glob(self.path(rounds.DIRECTORY, "*-seed*"))):
      for path in ckpt.list_checkpoints(directory):
        meta = self.read_meta(path)
        if meta is not None:
          step = self._round_step(path, meta, candidates)
          if step is not None:
            out[step.key] = step
    for path in sorted(glob.glob(self.path("runs", "*.json"))):
      record = read_json(path)
      if isinstance(record, dict):
        for step in self._record_steps(path, record, candidates):
          out.setdefault(step.key, step)  # a round file says more than the record
    order = {name: i for i, name in enumerate(self.config.strategies)}
    return sorted(out.values(), key=lambda s: (s.signature[0], order.get(s.signature[1], 99),
                                               s.signature[2]))

  def _views(self, candidates, w2c):
    if candidates is None:
      return None
    cams = with_poses(candidates[0], w2c)
    return cams

  def _names(self, candidates, indices):
    names = candidates[1] if candidates else None
    return [names[i] if (names and i is not None) else "new pose" for i in indices]

  def _round_step(self, path, meta, candidates):
    try:
      views = int(meta["step"])
      seed, name = int(meta["seed"]), str(meta["strategy"])
      chosen = meta["chosen"]
      train_w2c = np.asarray(meta["train_world_to_camera"], np.float64)
      scores = meta.get("scores")
    except (KeyError, TypeError, ValueError):
      return None
    notes = [self.inputs_error] if self.inputs_error else []
    train = proposals = None
    if candidates is not None:
      train = (self._views(candidates, train_w2c), self._names(candidates, meta["train"]))
      index = chosen.get("index")
      camera = self._views(candidates, [chosen["world_to_camera"]])[0]
      label = self._names(candidates, [index])[0]
      proposals = (Proposal(1, label, camera, index, float(chosen["score"])),)
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
        candidates=candidates, scores=None if scores is None else np.asarray(scores),
        score_name=score_name, proposals=proposals or (),
        train_images=tuple(meta["train"]), note="; ".join(notes))

  def _record_steps(self, path, record, candidates):
    try:
      name, seed = str(record["strategy"]), int(record["seed"])
      indices, w2c = list(record["indices"]), np.asarray(record["world_to_camera"], np.float64)
      scores = list(record["scores"])
    except (KeyError, TypeError, ValueError):
      return []
    out = []
    for views in range(1, len(indices)):
      train = proposals = None
      if candidates is not None:
        train = (self._views(candidates, w2c[:views]), self._names(candidates, indices[:views]))
        camera = self._views(candidates, w2c[views:views + 1])[0]
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

  def steps(self):
    from mfsample.lighting import strategies
    from mfsample.lighting.lights import uniform_light

    n = int(self.config.model.light_coeffs)
    uniform = ("uniform light", uniform_light(n))
    inputs = self.inputs or {}
    notes = [self.inputs_error] if self.inputs_error else []
    shared_ckpts = ckpt.list_checkpoints(self.path("shared"))
    shared_model = shared_ckpts[-1] if shared_ckpts else None
    shared_path = self.path("shared", "record.json")
    shared = read_json(shared_path)
    out = []
    base = dict(train=inputs.get("train"),
                train_images=tuple(range(len(inputs["train"][1]))) if "train" in inputs
                else None)
    if isinstance(shared, dict) and "q" in shared:
      out.append(Step(key="shared", title="first phase: the uniform light",
                      signature=(_stat(shared_path), _stat(shared_model) if shared_model
                                 else None, bool(inputs)),
                      model_path=shared_model, q=np.asarray(shared["q"], np.float64),
                      lights=(uniform,), note="; ".join(notes), **base))
    total = int(self.config.num_lights)
    for name in self.config.strategies:
      label = strategies.STRATEGIES[name].label if name in strategies.STRATEGIES else name
      done_path = self.path("runs", f"{name}.json")
      record = read_json(done_path)
      running = ckpt.list_checkpoints(self.path("runs", name))
      running_meta = self.read_meta(running[-1]) if running else None
      if isinstance(record, dict):
        phases, source = record.get("phases", []), done_path
      elif running_meta is not None:
        phases, source = [p for p in running_meta.get("phases", [])[1:] if p], running[-1]
      else:
        continue
      used = [uniform]
      for phase in phases:
        try:
          lights_now, xi = int(phase["lights"]), np.asarray(phase["light"], np.float64)
          q = np.asarray(phase["q"], np.float64)
        except (KeyError, TypeError, ValueError):
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
                        signature=(_stat(running[-1]), bool(inputs)), model_path=running[-1],
                        lights=tuple(used),
                        note="; ".join(notes + ["U over lights of this model is computed "
                                                "when the next light is chosen"]), **base))
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
