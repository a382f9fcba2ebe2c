"""The config file of `experiments/train.py`, shipped in the package.

`mfsample/configs/train.py` lists the variants
(`--config=configs/train.py:VARIANTS`); the installed command
`mfsample train` loads that file.
"""

from mfsample.configs.train import VARIANTS, get_config  # noqa: F401
