"""The config file of `experiments/camera_planning.py`, shipped in the package.

`mfsample/configs/camera_planning.py` lists the variants
(`--config=configs/camera_planning.py:VARIANTS`); the installed command
`mfsample camera-planning` loads that file.
"""

from mfsample.configs.camera_planning import VARIANTS, get_config  # noqa: F401
