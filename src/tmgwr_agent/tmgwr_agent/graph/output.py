"""One place that writes the graph commands' output lines.

The nodes' output is forwarded from one reader thread per process while the main thread
reports progress; ``print`` writes the text and the newline in two calls, so lines from
different threads could run into each other. :func:`say` writes each line in one call
under a lock.
"""

from __future__ import annotations

import sys
import threading

_LOCK = threading.Lock()


def say(text: str, file=None) -> None:
    """Write ``text`` and a newline to ``file`` (default stdout) at once, flushed."""
    f = file or sys.stdout
    with _LOCK:
        f.write(f"{text}\n")
        f.flush()
