"""Uncertainty maps of the test views and the next views to capture, for a dataset or a .ply.

  python experiments/uncertainty.py --config=configs/uncertainty.py --workdir=workdirs/unc
  python experiments/uncertainty.py --config=configs/uncertainty.py --workdir=workdirs/garden \
      --config.data.kind=colmap --config.data.path=~/captures/garden --config.data.downscale=8 \
      --config.posthoc.ply=~/models/garden/point_cloud.ply

Writes test/ (renders and U maps), next_views.json, next_views.png and results.json to the
workdir; running again on the same workdir resumes (docs/your_data.md).
"""

from absl import app, flags
from ml_collections import config_flags

from mfsample.next_views import run_uncertainty

_CONFIG = config_flags.DEFINE_config_file("config", None, "Uncertainty job config file.",
                                          lock_config=True)
_WORKDIR = flags.DEFINE_string("workdir", None, "Output directory.")
flags.mark_flags_as_required(["config", "workdir"])


def main(argv):
  if len(argv) > 1:
    raise app.UsageError(f"Unexpected arguments: {argv[1:]}")
  results = run_uncertainty(_CONFIG.value, _WORKDIR.value)
  print(f"{results['kind']} uncertainty of {results['scene']}: test PSNR "
        f"{results['test']['psnr']:.2f} dB, mean U {results['test']['mean_u']:.4g}")
  for t in results["top_k"]:
    print(f"  next view {t['rank']}: {t['name']} (U = {t['u']:.4g})")
  nv = results["next_views"]
  if nv["candidates"] == "unused":  # candidates with images: U against the model's error
    rho = nv["rho_u_error"]
    print("  Spearman rho of U against the model's error over the candidates: "
          + (f"{rho:.2f}" if rho is not None else
             f"undefined ({nv['num_candidates']} candidate(s); it needs 3 or more whose U and "
             "error are not all equal)"))
  files = results.get("files", {})
  if files:
    print(f"  viewers: {files['next_views']}/ (cameras.json for SuperSplat, transforms.json and "
          f"camera_path.json for nerfstudio, COLMAP text), {', '.join(files['uncertainty_ply'])}")
  print(f"written to {_WORKDIR.value}")


if __name__ == "__main__":
  app.run(main)
