"""Hostile inputs to the config checks of mfsample.config_checks.

For each entry point, a table of bad inputs and what they give: each row is a bad input and
its expected outcome, a clear error whose message names the field or the file, or a defined
behaviour (docs/reliability.md lists the same tables).
"""

import pytest

from mfsample import config_checks
from mfsample.config_checks import ConfigError

# ====================================================================== config checks


@pytest.mark.parametrize("check, value, message", [
    (lambda c: config_checks.check_bool(c, "x"), 1, "config.x = 1: must be True or False"),
    (lambda c: config_checks.check_str(c, "x", non_empty=True), "", "must be a non-empty string"),
    (lambda c: config_checks.check_str(c, "x"), None, "config.x = None: must be a string"),
    (lambda c: config_checks.check_floats(c, "x", 2), (1.0, "2"), "must be 2 finite numbers"),
    (lambda c: config_checks.check_floats(c, "x", 2, increasing=True), (1, 1),
     "strictly increasing"),
    (lambda c: config_checks.check_floats(c, "x", 3, minimum=0), (1, -1, 1),
     "must be 3 finite numbers >= 0"),
    (lambda c: config_checks.check_int(c, "x", minimum=1), True, "must be an integer >= 1"),
    (lambda c: config_checks.check_float(c, "x"), float("inf"), "must be a finite number"),
    (lambda c: config_checks.check_int(c, "y"), 0, "config.y: the config has no such field"),
])
def test_config_check_table(check, value, message):
  with pytest.raises(ConfigError, match=message):
    check({"x": value})
