"""Reading a file in a directory we own when someone else may have put something there
(the one helper of map_store and checkpoint): no final symbolic link is followed, a FIFO or
device is refused at once instead of waited on, only a regular file of bounded size is
read. Every refusal raises the caller's error class, naming the path and why."""

from __future__ import annotations

import errno
import os
import stat


def kind(mode: int) -> str:
    """What a file of this ``st_mode`` is, for a refusal ("a FIFO", "a directory", ...)."""
    for test, what in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISLNK, "a symbolic link")):
        if test(mode):
            return what
    return "not a regular file"


def read_regular(path: str, dir_fd: int | None, max_bytes: int, noun: str,
                 error: type[Exception]) -> bytes:
    """The bytes of ``path`` (relative to ``dir_fd`` when given), which must be a regular
    file of at most ``max_bytes``. FileNotFoundError passes through (the caller words it);
    anything else refused raises ``error`` with ``noun`` ("map", "checkpoint") in it."""
    flags = os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    try:
        fd = os.open(path, flags, dir_fd=dir_fd)
    except FileNotFoundError:
        raise
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise error(f"{path} is a symbolic link: refused ({noun}s are read only from "
                        "regular files)") from None
        raise error(f"{path}: cannot open: {exc.strerror}") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):            # before fdopen: a directory cannot be opened
        os.close(fd)
        raise error(f"{path} is {kind(st.st_mode)}, not a regular file: refused")
    with os.fdopen(fd, "rb", closefd=True) as f:
        if st.st_size > max_bytes:
            raise error(f"{path}: {st.st_size} bytes, more than a {noun} may have "
                        f"({max_bytes})")
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise error(f"{path}: larger than a {noun} may be ({max_bytes} bytes)")
    return data
