"""The one reader of the ``.npz`` files we did not just write ourselves (maps through
``load_map`` and ``initial_map``, checkpoints, ``--resume``): every array header is read
and checked *before* any array is allocated, so a crafted file is refused by name with its
reason instead of raising MemoryError (a 21 kB file may declare 10**12 float64 values).

For each member of the zip archive, without decompressing its data:

* the name ends in ``.npy`` and its uncompressed size (as the archive states it) is
  within the caller's cap;
* the ``.npy`` magic and header (``numpy.lib.format.read_magic`` and
  ``read_array_header_1_0`` / ``_2_0``, header length bounded): format 1.0 or 2.0;
* the dtype is a plain number or bool (:data:`KINDS`; no object, no structured dtype,
  so nothing can need a pickle) of at most :data:`MAX_ITEMSIZE` bytes;
* the shape's element count times the item size is exactly the data the member holds, and
  every array together stays within the cap.

Only then are the arrays read, with ``allow_pickle=False`` (the zip reader stops at the
stated size: a member cannot hold more than its header declared). Every refusal raises the
caller's error class (a ValueError subclass), naming the file, the member and why.
"""

from __future__ import annotations

import io
import math
import zipfile

import numpy as np
from numpy.lib import format as npy

KINDS = "biuf"               # bool, signed, unsigned, float
MAX_ITEMSIZE = 8             # bytes per value: up to float64 / int64
MAX_HEADER = 10_000          # bytes of a .npy header (numpy's own default limit)


def read_npz(data: bytes, what: str, max_bytes: int, error: type[ValueError],
             noun: str = "file") -> dict[str, np.ndarray]:
    """The arrays of the ``.npz`` bytes ``data`` (``what`` names the file in refusals),
    every header checked first (module docstring); ``max_bytes`` caps the file and the
    arrays it declares, together."""
    def refuse(text: str):
        raise error(f"{what}: {text}: refused")

    if len(data) > max_bytes:
        refuse(f"{len(data)} bytes, more than a {noun} may have ({max_bytes})")
    try:
        z = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise error(f"{what}: not a {noun} (not an .npz archive)") from None
    declared = 0
    with z:
        for info in z.infolist():
            member = info.filename
            if not member.endswith(".npy"):
                refuse(f"member {member!r} is not an array (.npy)")
            if info.file_size > max_bytes - declared:
                refuse(f"member {member!r} states {info.file_size} bytes uncompressed, more "
                       f"than a {noun} may hold ({max_bytes} in all)")
            try:
                with z.open(info) as f:
                    version = npy.read_magic(f)
                    read_header = {(1, 0): npy.read_array_header_1_0,
                                   (2, 0): npy.read_array_header_2_0}.get(version)
                    if read_header is not None:
                        shape, _, dtype = read_header(f, max_header_size=MAX_HEADER)
                        header = f.tell()
            except (ValueError, OSError, EOFError, zipfile.BadZipFile,
                    NotImplementedError) as exc:
                refuse(f"member {member!r}: unreadable array header ({exc})")
            if read_header is None:
                refuse(f"member {member!r}: .npy format {version}, not 1.0 or 2.0")
            if any(d < 0 for d in shape):
                refuse(f"member {member!r}: shape {shape}")
            if dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None \
                    or dtype.kind not in KINDS or dtype.itemsize > MAX_ITEMSIZE:
                refuse(f"member {member!r}: dtype {dtype} (only bool, integers and floats "
                       f"of at most {MAX_ITEMSIZE} bytes; no objects, no pickles)")
            count = math.prod(int(d) for d in shape)
            size = count * dtype.itemsize
            if size > max_bytes - declared:
                refuse(f"member {member!r} declares shape {shape} of {dtype}: {size} bytes, "
                       f"more than a {noun} may hold ({max_bytes})")
            if header + size != info.file_size:
                refuse(f"member {member!r} declares shape {shape} of {dtype} ({size} bytes) "
                       f"but holds {info.file_size - header} bytes of data")
            declared += size
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as arrays:
                return {k: arrays[k] for k in arrays.files}
        except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
            raise error(f"{what}: not a {noun} ({exc})") from None
