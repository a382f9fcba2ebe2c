"""Any 3DGS .ply rendered to PNG: its Gaussians, or their uncertainty (docs/your_data.md).

  python experiments/render_ply.py --ply=output/scene/point_cloud/iteration_30000/point_cloud.ply \
      --up=0,-1,0 --out=model.png
  python experiments/render_ply.py --ply=workdirs/scene/uncertainty_ply/model_colours.ply \
      --colour_by=u_share --properties=workdirs/scene/uncertainty_ply/per_gaussian.ply \
      --cameras=workdirs/scene/next_views/cameras.json --out=share.png

Renders from an orbit around the Gaussians (--views, --elevation, --up, --size) or from the
cameras of a 3DGS cameras.json (--cameras, --scale), the views side by side in one PNG.
The same command installed: `mfsample render-ply` (`mfsample.your_data.render_ply_command`).
"""

from mfsample.your_data.render_ply_command import main

if __name__ == "__main__":
  main()
