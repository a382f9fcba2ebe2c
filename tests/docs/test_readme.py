"""The docs run as written.

* The Python snippets of README.md and docs/ (one namespace per page).
* The shell commands of the pages in `COMMAND_PAGES`, from a fresh clone, on stand-ins of the
  captures the documented tools write. A page tags each of its ```bash blocks with the routes
  it belongs to, on the line before it: `<!-- doc-test: colmap -->` (alternatives, such as
  posing with COLMAP or with nerfstudio, are separate routes; `<!-- doc-test: skip -->` for a
  block no test can run). A route's blocks run in the page's order in a folder of their own
  that holds `experiments/` and `configs/` as a clone does (HOME is that folder, for `~`).
  Commands of other tools (`colmap`, `ns-process-data`, the 3DGS code, ...) are replaced by
  `STAND_INS`, which write what the tool writes, in its layout, from tiny random scenes;
  a job's command gets the job's `tiny` variant before its own variants and `TINY_AFTER` at
  its end, and datasets at absolute paths (`DATA`) are replaced by tiny stand-ins.
"""

import re
import shlex
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def _snippets(page):
  return re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)


# docs/api.md's snippets run once, as one program in a process of their own that also
# checks that they import no ml_collections and write no file
# (tests/core/test_api.py::test_the_api_page_is_a_program_without_configs_or_files).
SNIPPET_PAGES = [p for p in PAGES if _snippets(p) and p.name != "api.md"]


@pytest.mark.parametrize("page", SNIPPET_PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
@pytest.mark.slow
def test_python_snippets_run(page, tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)  # snippets that write files write them here
  namespace = {}
  for block in _snippets(page):
    exec(compile(block, str(page), "exec"), namespace)  # noqa: S102


# ------------------------------------------------------------------ shell commands

COMMAND_PAGES = ("docs/your_data.md", "docs/data.md")
_BLOCK = re.compile(r"^([ \t]*)```(?:bash|sh)\n(.*?)^[ \t]*```", flags=re.S | re.M)
_TAG = re.compile(r"<!--\s*doc-test:\s*([^>]*?)\s*-->\s*$")


def shell_blocks(page):
  """[(routes, commands)] of a page's ```bash blocks: the routes of the tag on the line
  before each (None: untagged; () for `skip`), and its commands with continuation lines
  joined and comments removed."""
  text = Path(page).read_text()
  out = []
  for match in _BLOCK.finditer(text):
    before = text[:match.start()].rstrip("\n").rsplit("\n", 1)[-1]
    tag = _TAG.search(before)
    routes = None
    if tag:
      routes = () if tag.group(1) == "skip" else tuple(
          r.strip() for r in tag.group(1).split(","))
    body = textwrap.dedent(match.group(2)).replace("\\\n", " ")
    commands, pending = [], ""
    for line in body.splitlines(keepends=True):
      pending += line
      try:  # a quoted argument may span lines (`python -c "..."`)
        words = shlex.split(pending, comments=True)
      except ValueError:
        continue
      pending = ""
      if words:
        commands.append(words)
    assert not pending, f"{page}: unclosed quotation in {pending!r}"
    out.append((routes, commands))
  return out


def _routes(page):
  names = []
  for routes, _ in shell_blocks(ROOT / page):
    names += [r for r in routes or () if r not in names]
  return names


def _option(words, name):
  """The value of `--name=value` or `--name value` (or `-n value`) in a command."""
  for i, word in enumerate(words):
    if word.startswith(name + "="):
      return word.split("=", 1)[1]
    if word == name:
      return words[i + 1]
  raise AssertionError(f"{shlex.join(words)}: no {name}")


# -- stand-ins of other tools' commands: each writes what the tool writes, in its layout.

BLACK = (0.0, 0.0, 0.0)  # 3DGS's and the `colmap` variants' background
SIZE = 96  # photographs of 96 x 96: images_8 of 12 x 12 (the loss's SSIM needs 11 x 11)


def _tiny_3dgs(clone):
  """A tiny COLMAP capture and the 3DGS model that renders it, made once per clone."""
  from mfsample.testing import write_tiny_capture

  made = clone / ".stand_in_3dgs"
  if not made.exists():
    write_tiny_capture(made, num_views=8, size=SIZE, background=BLACK)
  return made / "capture", made / "point_cloud.ply"


def _colmap_undistorter(words, clone):
  """`colmap image_undistorter --output_type COLMAP`: images/ and sparse/ (no images_N)."""
  from mfsample.testing import write_tiny_capture

  assert _option(words, "--output_type") == "COLMAP"
  write_tiny_capture(clone / ".stand_in_undistorter", num_views=8, size=SIZE, sparse="sparse",
                     background=BLACK)
  out = clone / _option(words, "--output_path")
  out.parent.mkdir(parents=True, exist_ok=True)
  shutil.move(clone / ".stand_in_undistorter" / "capture", out)


def _convert_py(words, clone):
  """3DGS's `convert.py -s scene`: COLMAP and its undistorter, images/ and sparse/0."""
  capture, _ = _tiny_3dgs(clone)
  shutil.copytree(capture, clone / _option(words, "-s"))


def _train_py(words, clone):
  """3DGS's `train.py -s scene -m out`: out/point_cloud/iteration_30000/point_cloud.ply."""
  _, ply = _tiny_3dgs(clone)
  out = clone / _option(words, "-m") / "point_cloud" / "iteration_30000"
  out.mkdir(parents=True)
  shutil.copy(ply, out / "point_cloud.ply")


def _ns_process_data(words, clone):
  """`ns-process-data images --camera-type pinhole`: transforms.json with nerfstudio's
  applied_transform, images/ and images_2, _4, _8 (its default downscales), sparse_pc.ply."""
  from mfsample.data import PointCloud, export_nerfstudio
  from mfsample.data.nerfstudio import NS_PROCESS_DATA_TRANSFORM
  from mfsample.testing import synthetic_views

  assert _option(words, "--camera-type") == "pinhole"
  views, truth = synthetic_views(8, size=SIZE, background=BLACK)
  points = PointCloud(np.asarray(truth.means, np.float32),
                      np.full((truth.means.shape[0], 3), 0.5, np.float32))
  export_nerfstudio(clone / _option(words, "--output-dir"), views, points,
                    applied_transform=NS_PROCESS_DATA_TRANSFORM, downscales=(2, 4, 8))


def _ns_train(words, clone):
  """`ns-train splatfacto --data scene`: outputs/scene/splatfacto/RUN/, whose
  dataparser_transforms.json re-centres and rescales the capture."""
  from mfsample._json import write_json

  data = Path(_option(words, "--data"))
  run = clone / "outputs" / data.name / words[1] / "RUN"
  run.mkdir(parents=True)
  transform = [[0.0, 1.0, 0.0, 0.1], [-1.0, 0.0, 0.0, -0.2], [0.0, 0.0, 1.0, 0.3]]
  write_json(run / "dataparser_transforms.json", {"transform": transform, "scale": 0.5})


STAND_INS = {
    ("colmap", "automatic_reconstructor"): lambda words, clone: None,  # (read only by the next)
    ("colmap", "image_undistorter"): _colmap_undistorter,
    ("python", "convert.py"): _convert_py,
    ("python", "train.py"): _train_py,
    ("ns-process-data", "images"): _ns_process_data,
    ("ns-train", "splatfacto"): _ns_train,
}


def _colmap_capture(path):
  from mfsample.testing import write_tiny_capture

  write_tiny_capture(path.parent / ".stand_in", num_views=8, size=SIZE, background=BLACK)
  shutil.move(path.parent / ".stand_in" / "capture", path)


def _blender_capture(path):
  from mfsample.data import export_blender
  from mfsample.testing import synthetic_views

  views, _ = synthetic_views(10, size=32)
  export_blender(path, views.subset(range(8)), split="train")
  export_blender(path, views.subset(range(8, 10)), split="test")


# Datasets the pages name, as tiny stand-ins in their layout (Mip-NeRF 360's without its
# images_N copies). `~/` is the clone's HOME; absolute paths are replaced in the command.
DATA = {
    "~/captures/garden": _colmap_capture,
    "/data/nerf_synthetic/lego": _blender_capture,
}
# Appended to every command of a job: the sizes a variant of the page sets beyond `tiny`.
TINY_AFTER = {
    "train.py": ("--config.model.init_points=300", "--config.model.max_gaussians=1024",
                 "--config.train.num_steps=40", "--config.densify.stop=30",
                 "--config.render.max_intersections=4096"),
}


def _job_command(words):
  """A job's command with its config's `tiny` variant first and `TINY_AFTER` at the end."""
  script = Path(words[1]).name
  out = []
  for word in words[1:]:
    if word.startswith("--config="):
      file, _, variants = word.split("=", 1)[1].partition(":")
      word = f"--config={file}:" + ",".join(["tiny", *filter(None, variants.split(","))])
    out.append(word)
  after = TINY_AFTER.get(script, ())
  given = {w.split("=")[0] for w in out}
  assert not given & {a.split("=")[0] for a in after}, "TINY_AFTER overrides the page"
  return [sys.executable, *out, *after]


def _run(words, clone, env):
  out = subprocess.run(words, cwd=clone, env=env, capture_output=True, text=True,
                       timeout=1200)
  assert out.returncode == 0 and "Traceback" not in out.stderr, (
      f"{shlex.join(words)} failed ({out.returncode}):\n{out.stdout[-3000:]}\n"
      f"{out.stderr[-6000:]}")
  return out


def run_route(page, route, clone):
  """Runs the commands of `route` on `page` in `clone`; [(command, CompletedProcess)]."""
  import os

  for name in ("experiments", "configs"):
    (clone / name).symlink_to(ROOT / name)
  env = dict(os.environ, HOME=str(clone), PYTHONPATH=str(ROOT))
  blocks = [commands for routes, commands in shell_blocks(ROOT / page) if route in (routes or ())]
  assert blocks, f"{page} has no block of route {route!r}"
  text = " ".join(shlex.join(c) for commands in blocks for c in commands)
  replaced = {}
  for name, make in DATA.items():
    if name in text:
      path = clone / name[2:] if name.startswith("~/") else clone / "stand_ins" / name[1:]
      path.parent.mkdir(parents=True, exist_ok=True)
      make(path)
      if not name.startswith("~/"):
        replaced[name] = str(path)
  done = []
  for commands in blocks:
    for words in commands:
      for name, path in replaced.items():
        words = [w.replace(name, path) for w in words]
      if words[0] == "python" and words[1].startswith("experiments/"):
        done.append((words, _run(_job_command(words), clone, env)))
      elif words[:2] == ["python", "-c"]:
        done.append((words, _run([sys.executable, *words[1:]], clone, env)))
      else:
        stand_in = STAND_INS.get(tuple(words[:2]))
        assert stand_in is not None, f"{page}: no stand-in for {shlex.join(words)}"
        stand_in(words, clone)
  return done


def test_every_command_block_of_the_command_pages_is_tagged():
  for page in COMMAND_PAGES:
    untagged = [c for routes, c in shell_blocks(ROOT / page) if routes is None]
    assert not untagged, f"{page}: untagged ```bash blocks {untagged}"


def test_blocks_are_read_as_a_shell_reads_them(tmp_path):
  page = tmp_path / "p.md"
  page.write_text("x\n\n   <!-- doc-test: a, b -->\n   ```bash\n   run --x=1 \\\n"
                  "       --y='two words'   # a comment\n   second\n   ```\n\n"
                  "```bash\nuntagged\n```\n<!-- doc-test: skip -->\n```sh\nskipped\n```\n")
  assert shell_blocks(page) == [(("a", "b"), [["run", "--x=1", "--y=two words"], ["second"]]),
                                (None, [["untagged"]]), ((), [["skipped"]])]


@pytest.mark.parametrize("page, route", [(p, r) for p in COMMAND_PAGES for r in _routes(p)],
                         ids=lambda v: v)
@pytest.mark.slow
def test_shell_commands_run(page, route, tmp_path):
  """The route's commands exit 0 without a traceback; every job writes its results."""
  pytest.importorskip("pycolmap")
  done = run_route(page, route, tmp_path)
  for words, _ in done:
    workdir = next((w.split("=", 1)[1] for w in words if w.startswith("--workdir=")), None)
    if workdir is not None:
      assert (tmp_path / workdir / "config.json").is_file(), shlex.join(words)
