"""The test harness's own promise about commands that hang in their teardown
(:meth:`ros_helpers.RosProcess.wait` with ``done``): a command that printed its verdict and
then hangs counts by its verdict, with a warning; one that never printed it still fails."""

from __future__ import annotations

import sys

import pytest
from ros_helpers import RosProcess

HANGS_AFTER_VERDICT = "import time; print('Transitioning successful', flush=True); time.sleep(600)"
HANGS_SILENT = "import time; print('waiting', flush=True); time.sleep(600)"


def python(code: str) -> RosProcess:
    return RosProcess([sys.executable, "-c", code], env={"PATH": "/usr/bin:/bin"},
                      name="python -c")


def test_a_command_hung_after_its_verdict_counts_by_it_with_a_warning():
    with python(HANGS_AFTER_VERDICT) as p:
        with pytest.warns(UserWarning, match="printed its verdict, then hung"):
            out = p.wait(timeout=60, done="Transitioning successful", teardown=1.0)
        assert p.hung_after_verdict and "Transitioning successful" in out
        assert not p.running()                   # stopped, not left behind


def test_a_command_hung_without_its_verdict_still_fails():
    with python(HANGS_SILENT) as p:
        with pytest.raises(AssertionError, match="did not exit within 2"):
            p.wait(timeout=2, done="Transitioning successful", teardown=1.0)
        assert not p.running()


def test_a_command_that_exits_is_judged_by_its_exit_code():
    with python("print('Transitioning successful'); raise SystemExit(3)") as p:
        with pytest.raises(AssertionError, match="exited with 3"):
            p.wait(timeout=60, done="Transitioning successful")
        assert not p.hung_after_verdict
