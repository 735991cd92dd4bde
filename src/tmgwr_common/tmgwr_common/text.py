"""Echoing what a user sent: a refusal quotes the request, never more than a readable
length of it (a 10 kB event name is not echoed back in full)."""

from __future__ import annotations

SHOWN = 40            # characters of a request echoed back


def shown(text: str, limit: int = SHOWN) -> str:
    """``text`` as a message quotes it: its repr, cut to ``limit`` characters (and then
    saying how long it was)."""
    r = repr(text)
    return r if len(r) <= limit else f"{r[:limit]}... ({len(text)} characters)"
