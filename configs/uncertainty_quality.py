"""The config file of `experiments/uncertainty_quality.py`, shipped in the package.

`mfsample/configs/uncertainty_quality.py` lists the variants
(`--config=configs/uncertainty_quality.py:VARIANTS`); the installed command
`mfsample uncertainty-quality` loads that file.
"""

from mfsample.configs.uncertainty_quality import VARIANTS, get_config  # noqa: F401
