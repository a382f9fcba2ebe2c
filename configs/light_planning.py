"""The config file of `experiments/light_planning.py`, shipped in the package.

`mfsample/configs/light_planning.py` lists the variants
(`--config=configs/light_planning.py:VARIANTS`); the installed command
`mfsample light-planning` loads that file.
"""

from mfsample.configs.light_planning import VARIANTS, get_config  # noqa: F401
