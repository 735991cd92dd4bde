"""Crafted ``.npz`` files (issue 24, point 2): real arrays, except that one member's
``.npy`` header declares another shape or dtype than the data it holds, as a hostile user
would write one (a 21 kB file whose header declares 10**12 float64 values)."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
from numpy.lib import format as npy

HUGE = (10 ** 12,)          # 8 TB of float64


def npy_member(array: np.ndarray, shape=None, descr=None) -> bytes:
    """The ``.npy`` bytes of ``array`` with its header's shape and dtype replaced."""
    buf = io.BytesIO()
    header = npy.header_data_from_array_1_0(array)
    if shape is not None:
        header["shape"] = tuple(shape)
    if descr is not None:
        header["descr"] = descr
    npy.write_array_header_1_0(buf, header)
    buf.write(np.ascontiguousarray(array).tobytes())
    return buf.getvalue()


def crafted_npz(path: Path, arrays: dict, member: str, shape=HUGE, descr=None,
                pad: int = 20_000) -> Path:
    """``arrays`` as an ``.npz`` at ``path`` whose ``member`` declares ``shape`` (and
    ``descr``); ``pad`` bytes of data (incompressible) added to that member."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, a in arrays.items():
            a = np.asarray(a)
            if name == member:
                data = npy_member(a, shape, descr) + np.random.default_rng(0).bytes(pad)
            else:
                data = npy_member(a)
            z.writestr(name + ".npy", data)
    return path
