"""Where the experiment commands write their results (``experiment``, ``demo``, ``bench``).

A module of its own so that :mod:`.cli`, which imports the commands, is imported by none
of them.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def write_json(result: dict, path: str | Path | None) -> None:
    """``result`` as indented JSON to ``path`` (its folder made), or to stdout for None
    or ``-``."""
    text = json.dumps(result, indent=1) + "\n"
    if path is None or str(path) == "-":
        sys.stdout.write(text)
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
