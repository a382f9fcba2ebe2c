"""Datasets by kind: one registry, `DATA_KINDS`, that every job reads.

A dataset is described by a frozen `DataSpec` (a job's `data` block, translated at its
boundary); `load_dataset(spec)` returns its training and test views and what the kind offers
beside them. What each kind offers is declared once, in its `DataKind`, and the jobs ask for
it rather than test kind names:

| kind       | what it is                                   | points | depth | oracle | lights |
| ---------- | -------------------------------------------- | ------ | ----- | ------ | ------ |
| synthetic  | random Gaussians rendered by mfsample        |        | yes   | yes    | yes*   |
| scene      | a built-in Mitsuba scene, captured on demand |        | yes   | yes    | yes    |
| blender    | NeRF Synthetic files (transforms_*.json)     |        |       |        |        |
| colmap     | a COLMAP capture (sparse/0, images_N/)       | yes    |       |        |        |
| llff       | a forward-facing LLFF capture                |        |       |        |        |
| nerfstudio | ns-process-data's transforms.json            | yes    |       |        |        |

"depth": exact metric depth and coverage (masks) of any camera (`capture`: the AUSE
benchmark's arc); "oracle": the ground truth of any new pose (`Dataset.oracle`: the
optimising planning strategies); "lights": images under any SH light (`load_light_data`:
light planning; *the diffuse shell shapes). A new kind is a loader and an entry here; a job
that needs a capability checks `DataKind.offers`.
"""

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from mfsample import settings_checks as sc
from mfsample.camera import Camera
from mfsample.data import synthetic
from mfsample.data._io import resolve_path
from mfsample.data.blender import load_blender
from mfsample.data.views import Views
from mfsample.planning.poses import SphereSpec, random_uv, spherical_camera

SYNTHETIC_SHAPES = ("random", "shell", "cloud")
SYNTHETIC_CAMERAS = ("orbit", "band")


@dataclasses.dataclass(frozen=True)
class SyntheticSpec:
  """Random ground-truth Gaussians rendered by mfsample (`DataSpec.kind = "synthetic"`).

  Attributes:
    shape: "random" (Gaussians uniform in the cube [-radius, radius]^3, random SH colour of
      `sh_degree`), "shell" (an opaque shell on the sphere of `radius`: every view sees one
      side of a closed surface) or "cloud" (a see-through cloud in the cube); diffuse shells
      and clouds offer images under any light too.
    num_gaussians: how many.
    seed: their seed.
    sh_degree: "random": the SH degree of their colour.
    radius: their sphere's radius, or the cube's half-side; the scene box is this + 0.2.
    cameras: "orbit" (a Fibonacci spiral of cameras around the origin; the test views in
      between) or "band" (uniform by area over the polar band `v_range`, seeded by
      `DataSpec.camera_seed`: the planning sphere, new poses on it).
    distance: the cameras' distance from the origin.
    v_range: "band": (v_min, v_max) of v = polar / pi.
    fov_x_deg: horizontal field of view in degrees.
  """

  shape: str = "random"
  num_gaussians: int = 200
  seed: int = 0
  sh_degree: int = 0
  radius: float = 0.6
  cameras: str = "orbit"
  distance: float = 3.0
  v_range: tuple = (0.1, 0.6)
  fov_x_deg: float = 40.0

  def __post_init__(self):
    sc.check_choice("SyntheticSpec.shape", self.shape, SYNTHETIC_SHAPES)
    sc.check_int("SyntheticSpec.num_gaussians", self.num_gaussians, minimum=1)
    sc.check_int("SyntheticSpec.seed", self.seed, minimum=0)
    sc.check_int("SyntheticSpec.sh_degree", self.sh_degree, minimum=0, maximum=3)
    radius = sc.check_float("SyntheticSpec.radius", self.radius, above=0.0)
    sc.check_choice("SyntheticSpec.cameras", self.cameras, SYNTHETIC_CAMERAS)
    sc.check_float("SyntheticSpec.distance", self.distance, above=radius)
    sc.set_field(self, "v_range", sc.check_floats("SyntheticSpec.v_range", self.v_range, 2,
                                                  minimum=0.0, maximum=1.0, increasing=True))
    sc.check_float("SyntheticSpec.fov_x_deg", self.fov_x_deg, above=0.0, below=180.0)


@dataclasses.dataclass(frozen=True)
class DataSpec:
  """Which views a job trains and tests on (a job's `data` block, typed).

  Attributes:
    kind: one of `DATA_KINDS`.
    path: the files' folder (relative: to the working directory), for the kinds of files.
    downscale: blender: integer image downscale; colmap, llff, nerfstudio: the
      pre-downscaled `images_{downscale}/` folder (1: `images/`).
    test_every: blender: every n-th test view.
    holdout_every: colmap, llff, nerfstudio: every n-th image (by name) is a test view.
    scene: scene: the `mfsample.scenes.get_scene` name.
    width, height: scene, synthetic: image size in pixels.
    num_train, num_test: scene, synthetic: training (candidate) and test cameras.
    camera_seed: scene, synthetic "band": seed of the training poses (test: + 1).
    spp: scene: Mitsuba samples per pixel.
    cache_dir: scene: the capture cache ("": $MFSAMPLE_CACHE or ~/.cache/mfsample/captures).
    background: RGB the images are composited on.
    init_bounds: blender: the cube (low, high) around the origin holding the scene.
    progress: progress bars of the captures.
    synthetic: `SyntheticSpec`.
  """

  kind: str = "scene"
  path: str = "data/nerf_synthetic/lego"
  downscale: int = 1
  test_every: int = 1
  holdout_every: int = 8
  scene: str = "default"
  width: int = 128
  height: int = 128
  num_train: int = 100
  num_test: int = 50
  camera_seed: int = 0
  spp: int = 36
  cache_dir: str = ""
  background: tuple = (1.0, 1.0, 1.0)
  init_bounds: tuple = (-1.3, 1.3)
  progress: bool = True
  synthetic: SyntheticSpec = SyntheticSpec()

  def __post_init__(self):
    sc.check_choice("DataSpec.kind", self.kind, tuple(DATA_KINDS))
    sc.check_str("DataSpec.path", self.path)
    for name in ("downscale", "test_every", "width", "height", "num_train", "num_test",
                 "spp"):
      sc.check_int(f"DataSpec.{name}", getattr(self, name), minimum=1)
    sc.check_int("DataSpec.holdout_every", self.holdout_every, minimum=2)
    sc.check_str("DataSpec.scene", self.scene, non_empty=True)
    sc.check_int("DataSpec.camera_seed", self.camera_seed, minimum=0, maximum=2**31 - 2)
    sc.check_str("DataSpec.cache_dir", self.cache_dir)
    sc.set_field(self, "background", sc.check_floats("DataSpec.background", self.background,
                                                     3, minimum=0.0, maximum=1.0))
    sc.set_field(self, "init_bounds", sc.check_floats("DataSpec.init_bounds",
                                                      self.init_bounds, 2, increasing=True))
    sc.check_bool("DataSpec.progress", self.progress)
    if not isinstance(self.synthetic, SyntheticSpec):
      raise sc.SettingsError("DataSpec.synthetic", self.synthetic, "a SyntheticSpec")

  @property
  def offers(self):
    """What the kind offers (`DataKind.offers`)."""
    return DATA_KINDS[self.kind].offers

  @property
  def name(self):
    """The scene's name in tables and figures."""
    return DATA_KINDS[self.kind].name(self)

  def replace(self, **changes):
    return dataclasses.replace(self, **changes)


class Dataset(NamedTuple):
  """Training and test views of one scene, and what its kind offers beside them.

  Attributes:
    train: `Views` to train on (the candidate pool of camera planning).
    test: `Views` to evaluate on.
    background: RGB tuple the images are composited on.
    bounds: (low [3], high [3]) box holding the scene: the random initial point cloud and
      the ACP grid live in it (a Mitsuba scene's cube around its bounding sphere, a COLMAP
      capture's box of its points, LLFF's of its frusta, NeRF Synthetic's `init_bounds`).
    points: the sparse SfM `mfsample.data.colmap.PointCloud` of a capture, else None.
    name: the scene's name.
    sphere: the `poses.SphereSpec` of the camera sphere (new poses of the optimising
      strategies, figures); fitted to the training cameras for files.
    oracle: camera -> [H, W, 3] ground truth at any pose, or None (files).
    world_transform: [3, 4] the transform a capture's tools applied to its world
      (nerfstudio's `applied_transform`), for files written back in its world; or None.
  """

  train: Views
  test: Views
  background: tuple
  bounds: tuple
  points: object = None
  name: str = ""
  sphere: SphereSpec | None = None
  oracle: Callable | None = None
  world_transform: np.ndarray | None = None


class DataKind(NamedTuple):
  """One kind of dataset: its loaders and what it offers.

  Attributes:
    summary: one line for the docs and for error messages.
    load: `DataSpec` -> `Dataset`.
    files: whether the dataset is files at `DataSpec.path` (a fixed pool of views).
    holdout: whether its test views are every `holdout_every`-th of one set of images (the
      Mip-NeRF 360 / 3DGS split of a capture).
    points: whether it brings sparse SfM points (for `init_from = "points"`).
    capture: optional `DataSpec` -> (cameras -> `Views` with exact depth and coverage, box
      of the scene): the ground truth of any camera.
    lights: optional (`DataSpec`, n) -> `mfsample.lighting.captures.LightData`: images
      under any SH light of n coefficients.
    name: optional `DataSpec` -> the scene's name (default: the kind).
  """

  summary: str
  load: Callable
  files: bool = False
  holdout: bool = False
  points: bool = False
  capture: Callable | None = None
  lights: Callable | None = None
  name: Callable = lambda spec: spec.kind

  @property
  def offers(self):
    """The capabilities: some of "points", "depth", "masks", "oracle", "lights"."""
    out = ("points",) if self.points else ()
    out += ("depth", "masks", "oracle") if self.capture is not None else ()
    return out + (("lights",) if self.lights is not None else ())


def load_dataset(spec: DataSpec) -> Dataset:
  """The views (and what comes with them) that `spec` describes."""
  if not isinstance(spec, DataSpec):
    raise ValueError(f"spec must be a DataSpec, got {type(spec).__name__}")
  return DATA_KINDS[spec.kind].load(spec)


def capture_views(spec: DataSpec, cameras: Camera):
  """(`Views` [C] of the ground truth at `cameras`, with exact depth and coverage; the box
  of the scene) for a kind that offers depth (ValueError otherwise)."""
  kind = DATA_KINDS[spec.kind]
  if kind.capture is None:
    raise ValueError(f"data kind {spec.kind!r} has no ground truth at new cameras (kinds "
                     f"with one: {', '.join(kinds_offering('depth'))})")
  return kind.capture(spec)(cameras)


def load_light_data(spec: DataSpec, light_coeffs):
  """The `LightData` (basis images of fixed cameras) of a kind that offers lights."""
  kind = DATA_KINDS[spec.kind]
  if kind.lights is None:
    raise ValueError(f"data kind {spec.kind!r} has no images under new lights (kinds with "
                     f"them: {', '.join(kinds_offering('lights'))})")
  return kind.lights(spec, int(light_coeffs))


def kinds_offering(capability):
  """The names of the kinds that offer `capability` ("points", "depth", "oracle", ...)."""
  return tuple(name for name, kind in DATA_KINDS.items() if capability in kind.offers)


def _box(radius, center=(0.0, 0.0, 0.0)):
  center = np.asarray(center, np.float64)
  return center - radius, center + radius


# ------------------------------------------------------------------------- synthetic


def _synthetic_truth(s: SyntheticSpec):
  """The ground-truth `Gaussians` of a `SyntheticSpec`."""
  if s.shape == "random":
    return synthetic.synthetic_gaussians(s.num_gaussians, s.seed, s.sh_degree, radius=s.radius)
  return synthetic.synthetic_scene(s.num_gaussians, s.seed, radius=s.radius, shape=s.shape)


def _synthetic_sphere(spec: DataSpec):
  s = spec.synthetic
  return SphereSpec(radius=s.distance, v_range=s.v_range, fov_x=math.radians(s.fov_x_deg),
                    width=spec.width, height=spec.height)


def _synthetic_cameras(spec: DataSpec, test):
  """The training (or test) cameras of a synthetic dataset."""
  s = spec.synthetic
  num = spec.num_test if test else spec.num_train
  if s.cameras == "orbit":
    return synthetic.orbit_cameras(num, spec.width, spec.height, s.distance,
                                   fov_x=math.radians(s.fov_x_deg), offset=0.37 if test else 0.0)
  sphere = _synthetic_sphere(spec)
  uv = random_uv(np.random.default_rng([spec.camera_seed, int(test)]), num, sphere)
  return spherical_camera(jnp.asarray(uv, jnp.float32), sphere)


def _synthetic_capture(spec: DataSpec):
  truth = _synthetic_truth(spec.synthetic)
  box = _box(spec.synthetic.radius + 0.2)

  def capture(cameras, names=None):
    return synthetic.render_views(truth, cameras, spec.background, names=names), box

  return capture


# A pure function of its spec that the viewer and the tests load again and again (each load
# renders every view); what it returns is immutable (JAX arrays, a read-only box).
@functools.lru_cache(maxsize=8)
def _synthetic(spec: DataSpec):
  """Random ground-truth Gaussians seen from their cameras; any pose has a ground truth."""
  capture = _synthetic_capture(spec)
  s = spec.synthetic
  if s.cameras == "orbit":
    names = ([f"view_{i:03d}" for i in range(spec.num_train)],
             [f"test_{i:03d}" for i in range(spec.num_test)])
  else:  # the sphere's random streams
    names = ([f"synthetic-0-{i}" for i in range(spec.num_train)],
             [f"synthetic-1-{i}" for i in range(spec.num_test)])
  train, box = capture(_synthetic_cameras(spec, False), names[0])
  test, _ = capture(_synthetic_cameras(spec, True), names[1])
  truth = _synthetic_truth(s)
  sphere = _synthetic_sphere(spec) if s.cameras == "band" else SphereSpec.from_cameras(
      train.cameras)
  for corner in box:
    corner.setflags(write=False)
  return Dataset(train, test, spec.background, box, name="synthetic", sphere=sphere,
                 oracle=synthetic.Oracle(truth, spec.background))


def _synthetic_lights(spec: DataSpec, n):
  from mfsample.lighting.captures import synthetic_light_data

  return synthetic_light_data(_synthetic_truth(spec.synthetic), spec.synthetic.seed,
                              _synthetic_cameras(spec, False), _synthetic_cameras(spec, True),
                              n, bounds=_box(spec.synthetic.radius + 0.2))


# ------------------------------------------------------------------------- blender


def _blender(spec: DataSpec):
  """A NeRF Synthetic scene (`load_blender`), every `test_every`-th test view."""
  path = resolve_path(spec.path)
  if not (path / "transforms_train.json").is_file():
    raise FileNotFoundError(
        f"No NeRF Synthetic scene at {path} (data.path={spec.path!r}; relative paths are "
        "resolved against the working directory). Expected transforms_train.json there.")
  train = load_blender(str(path), "train", downscale=spec.downscale, background=spec.background)
  test = load_blender(str(path), "test", downscale=spec.downscale, background=spec.background)
  if spec.test_every > 1:
    test = test.subset(range(0, len(test), spec.test_every))
  lo, hi = spec.init_bounds
  bounds = (np.full(3, lo), np.full(3, hi))
  return _with_sphere(Dataset(train, test, spec.background, bounds, name=path.name))


def _with_sphere(dataset: Dataset):
  """A dataset of files with the sphere of its figures: fitted to its training cameras, about
  the middle of its box (the cameras of a capture look at the scene, not at the origin)."""
  center = 0.5 * (np.asarray(dataset.bounds[0], np.float64)
                  + np.asarray(dataset.bounds[1], np.float64))
  return dataset._replace(sphere=SphereSpec.from_cameras(dataset.train.cameras, center))


# ------------------------------------------------------------------------- colmap, llff


def holdout_split(num, every):
  """(train indices, test indices) of `num` views: every `every`-th view from the first is a
  test view (Mip-NeRF 360 and 3DGS hold out every 8th image of a capture sorted by name)."""
  every = int(every)
  if every < 2:
    raise ValueError(f"holdout_every = {every}: must be an integer >= 2")
  index = np.arange(num)
  test = index[index % every == 0]
  train = index[index % every != 0]
  if len(train) == 0:
    raise ValueError(f"{num} view(s) and holdout_every = {every} leave no training view")
  return train, test


def _split(views, spec, bounds, points=None, world_transform=None):
  train, test = holdout_split(len(views), spec.holdout_every)
  bounds = tuple(np.asarray(b, np.float32) for b in bounds)
  return _with_sphere(Dataset(views.subset(train), views.subset(test), spec.background, bounds,
                              points, resolve_path(spec.path).name,
                              world_transform=world_transform))


def _colmap(spec: DataSpec):
  """A COLMAP capture (`load_colmap`): the held-out split, its sparse points and their box."""
  from mfsample.data.colmap import load_colmap

  views, points = _with_downscale(spec, lambda: load_colmap(
      resolve_path(spec.path), factor=spec.downscale, background=spec.background))
  return _with_points(views, points, spec)


def _with_downscale(spec: DataSpec, load):
  """`load()`, an image folder that is missing and cannot be made named with its field."""
  from mfsample.data.downscaled import MissingImageFolder

  try:
    return load()
  except MissingImageFolder as e:
    raise MissingImageFolder(f"{e} [config.data.downscale = {spec.downscale}: N reads "
                             "images_N/, 1 images/]") from None


def _nerfstudio(spec: DataSpec):
  """A nerfstudio capture (`load_nerfstudio`, ns-process-data's transforms.json): the
  held-out split, its `ply_file_path` points and their box, its `applied_transform`."""
  from mfsample.data._io import read_json
  from mfsample.data.nerfstudio import applied_transform, load_nerfstudio

  path = resolve_path(spec.path)
  views, points = _with_downscale(spec, lambda: load_nerfstudio(
      path, factor=spec.downscale, background=spec.background))
  meta = read_json(path if path.suffix == ".json" else path / "transforms.json")
  world = applied_transform(meta)[:3] if "applied_transform" in meta else None
  return _with_points(views, points, spec, world)


def _with_points(views, points, spec, world_transform=None):
  """A capture with SfM points: the box of its points (of its cameras without points)."""
  if len(points):
    bounds = points.box()
  else:  # no points: the box around the cameras
    centers = np.asarray(views.cameras.center, np.float64)
    radius = scene_extent(views.cameras)
    bounds = (centers.mean(0) - radius, centers.mean(0) + radius)
  return _split(views, spec, bounds, points, world_transform)


def _llff(spec: DataSpec):
  """A forward-facing LLFF capture (`load_llff`): the held-out split, the frusta's box."""
  from mfsample.data.llff import load_llff

  views, depth_bounds = _with_downscale(spec, lambda: load_llff(resolve_path(spec.path),
                                                                 factor=spec.downscale))
  return _split(views, spec, frustum_box(views.cameras, depth_bounds))


def frustum_box(cameras: Camera, depth_bounds):
  """(low [3], high [3]) around what the cameras see between their near and far depths.

  Args:
    cameras: `Camera` batched over V.
    depth_bounds: [V, 2] (near, far) camera z-depths.
  """
  w2c = np.asarray(cameras.world_to_camera, np.float64)
  rot, t = w2c[:, :3, :3], w2c[:, :3, 3]
  fx, fy, cx, cy = (np.asarray(getattr(cameras, k), np.float64)[:, None]
                    for k in ("fx", "fy", "cx", "cy"))
  u = np.array([0.0, cameras.width, 0.0, cameras.width])[None]
  v = np.array([0.0, 0.0, cameras.height, cameras.height])[None]
  rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u + cx)], -1)  # [V, 4, 3]
  corners = []
  for d in (0, 1):
    cam = rays * np.asarray(depth_bounds, np.float64)[:, d, None, None]
    corners.append(np.einsum("vji,vcj->vci", rot, cam - t[:, None]))  # R^T (x - t)
  corners = np.concatenate(corners, axis=1).reshape(-1, 3)
  return corners.min(0), corners.max(0)


# ------------------------------------------------------------------------- scene


def _scenes():
  try:
    from mfsample import scenes
  except ImportError as err:
    raise ImportError("data.kind = 'scene' needs mfsample.scenes and, for new captures, the "
                      "optional Mitsuba extra (pip install 'mfsample[scenes]')") from err
  return scenes


def _scene_capture(spec: DataSpec):
  scenes = _scenes()
  scene = scenes.get_scene(spec.scene)
  cache = str(resolve_path(spec.cache_dir)) if spec.cache_dir else None
  kwargs = dict(spp=spec.spp, cache_dir=cache, background=spec.background,
                progress=spec.progress)
  box = _box(float(scene.radius), scene.center)

  def capture(cameras):
    return scenes.capture_views(scene, cameras, **kwargs), box

  return capture


def _scene(spec: DataSpec):
  """A built-in Mitsuba scene (`mfsample.scenes`), captured at its candidate and test
  cameras; any new pose is captured on demand."""
  scenes = _scenes()
  scene = scenes.get_scene(spec.scene)
  w, h = spec.width, spec.height
  capture = _scene_capture(spec)
  train, box = capture(scene.candidate_cameras(w, h, num=spec.num_train, seed=spec.camera_seed))
  test, _ = capture(scene.test_cameras(w, h, num=spec.num_test, seed=spec.camera_seed + 1))
  cache = str(resolve_path(spec.cache_dir)) if spec.cache_dir else None
  return Dataset(train, test, spec.background, box, name=scene.name,
                 sphere=SphereSpec.from_scene(scene, w, h),
                 oracle=scenes.Oracle(scene, spp=spec.spp, cache_dir=cache,
                                      background=spec.background))


def _scene_lights(spec: DataSpec, n):
  from mfsample.lighting.captures import scene_light_data

  return scene_light_data(spec, n)


# ------------------------------------------------------------------------- the kinds

DATA_KINDS = {
    "synthetic": DataKind("random Gaussians rendered by mfsample (no files)", _synthetic,
                          capture=_synthetic_capture, lights=_synthetic_lights),
    "blender": DataKind("a NeRF Synthetic scene (transforms_*.json)", _blender, files=True,
                        name=lambda spec: resolve_path(spec.path).name),
    "scene": DataKind("a built-in Mitsuba scene, captured on demand", _scene,
                      capture=_scene_capture, lights=_scene_lights,
                      name=lambda spec: spec.scene),
    "colmap": DataKind("a COLMAP capture (sparse/0, images_N/)", _colmap, files=True,
                       holdout=True, points=True, name=lambda spec: resolve_path(spec.path).name),
    "llff": DataKind("a forward-facing LLFF capture (poses_bounds.npy)", _llff, files=True,
                     holdout=True, name=lambda spec: resolve_path(spec.path).name),
    "nerfstudio": DataKind("a nerfstudio capture (ns-process-data's transforms.json)",
                           _nerfstudio, files=True, holdout=True, points=True,
                           name=lambda spec: resolve_path(spec.path).name),
}
# The kinds that are files at `DataSpec.path`: fixed pools of views.
FILE_KINDS = tuple(name for name, kind in DATA_KINDS.items() if kind.files)


# ------------------------------------------------------------------------- helpers


# Camera centres whose spread is at most this fraction of their distance from the origin are
# one point (one camera, a tripod turning about one point, float32 round-off of the poses,
# ~1e-7 of that distance): their spread measures nothing about the scene.
COINCIDENT_SPREAD = 1e-3


def scene_extent(cameras: Camera):
  """The scene extent of 3DGS: 1.1 x the largest distance of a camera centre from their mean.

  Scales the position learning rate, B_hat of the centres, and densification thresholds.

  A layout with no spread to measure (one camera, cameras turning about one point: a spread
  at most `COINCIDENT_SPREAD` of the distance of their mean centre from the origin) falls back
  to 1.1 x that distance, the distance to the world's origin being then the only length the
  cameras give.

  Args:
    cameras: `Camera` batched over [V] (or one camera).

  Returns:
    the extent (float, world units), > 0.

  Raises:
    ValueError: the camera centres all lie at the origin (no spread, no distance): the
      extent must then be given.
  """
  # In float64 from the stored poses, not from `Camera.center` (float32, computed by XLA):
  # the extent goes into the sampler's spec that checkpoints record, so it must come out
  # bit for bit the same in every process, on every device and with any XLA settings.
  w2c = np.asarray(cameras.world_to_camera, np.float64).reshape(-1, 4, 4)
  centers = -np.einsum("vji,vj->vi", w2c[:, :3, :3], w2c[:, :3, 3])
  mean = centers.mean(0)
  radius = float(np.max(np.linalg.norm(centers - mean, axis=-1)))
  distance = float(np.linalg.norm(mean))
  if radius <= COINCIDENT_SPREAD * distance:
    radius = distance
  if not radius > 0.0:
    raise ValueError(f"scene_extent: the {len(centers)} camera centres all lie at the origin, "
                     "so neither their spread nor their distance measures the scene; give the "
                     "extent (`extent=`; `config.data.extent` in a training config, "
                     "`config.model.extent` in a lighting one).")
  return 1.1 * radius


def to_device(views: Views):
  """`Views` with jnp arrays (the step indexes them inside jit)."""
  return views.replace(images=jnp.asarray(views.images, jnp.float32),
                       cameras=jax.tree.map(jnp.asarray, views.cameras))
