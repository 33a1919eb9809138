"""The command check every axis uses: finite and inside the limits, or a clear error."""

import math

import pytest

from semlab.protocols import check_command


@pytest.mark.parametrize("value", [0.0, 50.0, 100.0])
def test_commands_inside_the_limits_pass(value):
    assert check_command(value, (0.0, 100.0)) == value


@pytest.mark.parametrize("value, words", [(math.nan, "not finite"), (math.inf, "not finite"),
                                          (-0.1, "outside"), (100.01, "outside"), ("x", "not a number")])
def test_bad_commands_are_refused_with_a_reason(value, words):
    with pytest.raises(ValueError, match=words):
        check_command(value, (0.0, 100.0), name="x piezo")
