#!/usr/bin/env bash
# Stages, on a machine with the package registries, what the device check
# (benchmarks/gpu_check.py) needs on a GPU machine that reaches none: run it from the
# repository root, then copy the repository with these git-ignored folders to the GPU machine.
#
#   benchmarks/gpu_prepare.sh [GARDEN_NPZ [LEGO_DIR]]
#
#   .whl/                        wheels of mfsample's dependencies that the GPU machines lack
#                                (pure Python: ml-collections, pypng, dm-pix, plyfile)
#   workdirs/gpudata/test_garden.npz   gsplat's garden workload, when GARDEN_NPZ is given
#   workdirs/gpudata/lego/       NeRF Synthetic lego's training views (400 x 400 files) and one
#                                test view, when LEGO_DIR is given (the step's scene)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
  --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
  --platform manylinux2014_x86_64 -d .whl ml-collections pypng dm-pix plyfile
mkdir -p workdirs/gpudata
if [[ $# -ge 1 ]]; then
  install -m 644 "$1" workdirs/gpudata/test_garden.npz
fi
if [[ $# -ge 2 ]]; then
  lego=workdirs/gpudata/lego
  if [[ -d $lego ]]; then chmod -R u+w "$lego"; rm -rf "$lego"; fi
  mkdir -p "$lego/test"
  cp -r "$2/train" "$2/transforms_train.json" "$lego/"
  chmod -R u+w "$lego"
  # One test view: the step times training only, but the loader reads the test split too.
  python3 - "$2" "$lego" <<'EOF'
import json, shutil, sys
src, dst = sys.argv[1:]
meta = json.load(open(f"{src}/transforms_test.json"))
meta["frames"] = meta["frames"][:1]
shutil.copy(f"{src}/{meta['frames'][0]['file_path']}.png", f"{dst}/test/")
json.dump(meta, open(f"{dst}/transforms_test.json", "w"))
EOF
fi
ls -l .whl workdirs/gpudata
du -sh .whl workdirs/gpudata
