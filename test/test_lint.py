"""Lint: `ruff check` over every Python file of the repository (rules and the one quote
style in ruff.toml). Run it by hand with `source tools/env.sh && ruff check .`; `ruff check
--fix .` repairs quotes and import order."""

import shutil
import subprocess

import pytest
from ros_helpers import ROOT


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.fail("ruff is not installed: run tools/bootstrap.sh (requirements/python.txt)")
    proc = subprocess.run([ruff, "check", "--no-cache", "--output-format", "concise", "."],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
