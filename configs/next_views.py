"""The config file of `experiments/next_views.py`, shipped in the package.

`mfsample/configs/next_views.py` lists the variants
(`--config=configs/next_views.py:VARIANTS`); the installed command
`mfsample next-views` loads that file.
"""

from mfsample.configs.next_views import VARIANTS, get_config  # noqa: F401
