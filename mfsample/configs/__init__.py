"""The jobs' config files, shipped with the package: one per job, each `get_config(variant)`.

`mfsample <job> --config=VARIANTS` loads the job's file here (`mfsample.cli`); the clone's
`configs/*.py`, which `python experiments/<job>.py --config=configs/<job>.py:VARIANTS`
loads, are the same files. Each docstring lists the job's variants.
"""
