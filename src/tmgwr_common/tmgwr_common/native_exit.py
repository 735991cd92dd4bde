"""An exit the C library carries out on its own: POSIX timers that end the process with a
chosen code, and say why, without Python.

A Python thread (``threading.Timer``) cannot end a process whose main thread hangs inside a
C call that holds the GIL (a middleware call of rclpy's pybind11 layer): it never gets the
interpreter back. :mod:`faulthandler`'s watchdog runs without the GIL but can only exit
with code 1. Here ``timer_create(SIGEV_THREAD)`` runs a C function in a fresh thread of the
C library when the timer expires: ``puts(message)`` (the C ``stdout`` made unbuffered
first), then ``_exit(code)``. Neither touches the interpreter.

:func:`arm` sets both timers; the call it returns deletes them. Where the C library has no
``timer_create`` (not glibc, not Linux), :func:`available` is false and :func:`arm` raises
OSError.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from typing import Callable

CLOCK_MONOTONIC = 1
SIGEV_THREAD = 2
_IONBF = 2


class _SigVal(ctypes.Union):
    _fields_ = [("sival_int", ctypes.c_int), ("sival_ptr", ctypes.c_void_p)]


class _SigEvThread(ctypes.Structure):
    _fields_ = [("function", ctypes.c_void_p), ("attribute", ctypes.c_void_p)]


class _SigEvUnion(ctypes.Union):
    _fields_ = [("pad", ctypes.c_int * 12), ("tid", ctypes.c_int), ("thread", _SigEvThread)]


class _SigEvent(ctypes.Structure):
    """Linux's ``struct sigevent`` (64 bytes)."""
    _fields_ = [("value", _SigVal), ("signo", ctypes.c_int), ("notify", ctypes.c_int),
                ("un", _SigEvUnion)]


class _TimeSpec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


class _ITimerSpec(ctypes.Structure):
    _fields_ = [("interval", _TimeSpec), ("value", _TimeSpec)]


def _libc():
    libc = ctypes.CDLL(None, use_errno=True)       # the process's own C library
    if not hasattr(libc, "timer_create"):         # glibc before 2.34 keeps it in librt
        libc = ctypes.CDLL(ctypes.util.find_library("rt") or "librt.so.1", use_errno=True)
    return libc


def available() -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        _libc()
    except OSError:
        return False
    return True


def _timer(libc, function: int, value: _SigVal, seconds: float) -> ctypes.c_void_p:
    ev = _SigEvent()
    ev.value = value
    ev.notify = SIGEV_THREAD
    ev.un.thread.function = function
    timer = ctypes.c_void_p()
    if libc.timer_create(CLOCK_MONOTONIC, ctypes.byref(ev), ctypes.byref(timer)) != 0:
        raise OSError(ctypes.get_errno(), "timer_create failed")
    spec = _ITimerSpec()
    spec.value.tv_sec = int(seconds)
    spec.value.tv_nsec = int((seconds - int(seconds)) * 1e9)
    if libc.timer_settime(timer, 0, ctypes.byref(spec), None) != 0:
        libc.timer_delete(timer)
        raise OSError(ctypes.get_errno(), "timer_settime failed")
    return timer


def arm(seconds: float, code: int, message: str, say_before: float = 0.5
        ) -> Callable[[], None]:
    """In ``seconds`` s, end the process with exit code ``code``; ``say_before`` s earlier,
    print ``message`` on stdout. Returns the call that cancels both (idempotent)."""
    if not available():
        raise OSError("no POSIX timers with SIGEV_THREAD on this platform")
    libc = _libc()
    libc.timer_create.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
    libc.timer_settime.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p,
                                   ctypes.c_void_p]
    libc.timer_delete.argtypes = [ctypes.c_void_p]
    libc.setvbuf.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int, ctypes.c_size_t]
    stdout = ctypes.c_void_p.in_dll(libc, "stdout")
    libc.setvbuf(stdout, None, _IONBF, 0)          # puts writes at once (nothing flushes)
    text = ctypes.create_string_buffer(message.encode(errors="replace"))
    puts = ctypes.cast(libc.puts, ctypes.c_void_p).value
    exit_ = ctypes.cast(libc._exit, ctypes.c_void_p).value
    timers = [_timer(libc, puts, _SigVal(sival_ptr=ctypes.addressof(text)),
                     max(0.0, seconds - say_before) or 1e-9),
              _timer(libc, exit_, _SigVal(sival_int=int(code)), seconds)]

    def cancel() -> None:
        while timers:
            libc.timer_delete(timers.pop())
        text.raw                                   # noqa: B018 -- kept alive until here
    return cancel
