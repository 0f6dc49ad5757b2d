"""The house's one number predicate (``core.checks.is_real`` / ``is_integer``) behind the
envs' own checks: a bool is never a number, a string never either."""

import numpy as np
import pytest

from machining_envs.core.actions import ActionMap
from machining_envs.core.checks import PY_NUMBER_TYPES, is_integer, is_real
from machining_envs.core.env import check_episode_time
from machining_envs.core.vector import check_num_envs
from machining_envs.core.workpieces import DepthProfile


def test_is_real_and_is_integer():
    assert is_real(1) and is_real(2.5) and is_real(np.float32(1.0)) and is_real(np.int64(3))
    assert not is_real(True) and not is_real("1") and not is_real(None)
    assert not is_real(np.float32(1.0), PY_NUMBER_TYPES) and is_real(1.5, PY_NUMBER_TYPES)
    assert is_integer(np.int64(3)) and not is_integer(True) and not is_integer(3.0)


@pytest.mark.parametrize("bad", [True, "2", None])
def test_a_bool_or_a_string_is_no_setting(bad):
    with pytest.raises(ValueError, match="decades"):
        ActionMap(0.0, 1.0, scale="log", decades=bad)
    with pytest.raises(ValueError, match="segment_mm"):
        DepthProfile.steps(segment_mm=bad)
    with pytest.raises(ValueError, match="max_episode_time_s"):
        check_episode_time(bad)
    with pytest.raises(TypeError, match="num_envs"):
        check_num_envs(bad)
