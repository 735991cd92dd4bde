"""The stop request of a node's process: SIGINT and SIGTERM only ask its main loop to stop
(:class:`StopSignals`, read by :func:`tmgwr_common.node.run`).

Standard library only, so that a node's first import installs it: a node spends its first
second importing numpy, rclpy and numba, and ``ros2 launch`` sends SIGINT to every node as
soon as one of them fails, so a node still importing when another refuses its parameters
must stop cleanly too (with the handler installed after those imports it printed a
KeyboardInterrupt traceback from inside ``import rclpy``). ``maze_sim`` and
:mod:`tmgwr_agent.nodes` import this module before anything else.
"""

from __future__ import annotations

import sys
from pathlib import Path


class StopSignals:
    """SIGINT and SIGTERM as a request to stop, nothing more: the handler sets
    :attr:`received` and the main loop of :func:`tmgwr_common.node.run` ends at its next
    turn (at most its
    spin timeout later).

    rclpy's own handler shuts the context down from the signal, possibly while a callback
    runs (its next publish fails: ``[FATAL] Exception in 'subscriptions' callback``), and
    then lets a second SIGINT raise KeyboardInterrupt wherever the node is, e.g. while the
    learner saves its map. A terminal's Ctrl-C under ``ros2 launch`` sends exactly that: one
    SIGINT from the terminal to the whole process group, one more from the launch. Here a
    callback always completes, the context is shut down after the node is destroyed, and
    every further signal is just counted."""

    def __init__(self):
        self.received: str | None = None
        self.count = 0
        self.installed = False

    def install(self) -> "StopSignals":
        import signal
        if not self.installed:
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, self._handler)
            self.installed = True
        return self

    def _handler(self, signum, frame) -> None:          # noqa: ARG002
        import signal
        self.count += 1
        self.received = self.received or signal.Signals(signum).name

    def ignore_from_now(self) -> None:
        """Ignore both signals for the rest of the process: Python's finalization resets a
        Python handler to the default action (a late SIGINT would kill the process at exit
        with code -2), an ignored signal it leaves ignored."""
        import signal
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)


def started_by_ros2_run(argv0: str | None = None) -> bool:
    """Whether this process is a node's installed executable, what ``ros2 run`` and
    ``ros2 launch`` start: ``<prefix>/lib/<package>/<executable>``."""
    argv0 = sys.argv[0] if argv0 is None and sys.argv else argv0
    return bool(argv0) and Path(argv0).parent.parent.name == "lib"


#: The process's stop request. Installed here, at import, in a node's own process (a
#: Ctrl-C while the node still imports numba must not print a KeyboardInterrupt
#: traceback), and by :func:`tmgwr_common.node.run` in any other; never in a tool that
#: merely imports this module (``./tmgwr up``, pytest keep their own Ctrl-C).
STOP = StopSignals()
if started_by_ros2_run():
    STOP.install()
