"""The CDR bytes of the per-step messages, read and written without rclpy's message objects.

rclpy turns every message it takes into a Python object field by field (the generated
class's ``__init__``, then one property setter per field, nested messages included) and
every message it publishes back into C the same way, then serializes it. For the ring's
small per-step messages that conversion is most of a node's callback (docs/benchmarks.md,
Benchmarks). The ring nodes therefore take and publish the serialized message itself,
which rclpy supports as it is (``create_subscription(..., raw=True)`` hands the callback
the CDR bytes; ``Publisher.publish(bytes)`` publishes them as they are), and this module
reads and writes those bytes.

A :class:`Codec` is made from the generated message class alone: its ``SLOT_TYPES`` and
field names (from the ``.msg`` files, so the layout is defined in one place) give the
fields in order, and the codec compiles one reader and one writer for them (as rosidl
generates its converters). The wire format is what rmw_fastrtps writes: the 4-byte
encapsulation header (CDR, little endian), then every field in order, each primitive
aligned to its size (8 at most) from the start of the payload; a string is its length
with the terminating NUL (uint32), the bytes and the NUL; a sequence its length (uint32),
then its elements, aligned to their size when there is at least one. Nothing else is
written: the bytes decode with rclpy's ``deserialize_message`` to the same message, and
a message rclpy serialized reads back to the same values (``test/test_cdr.py``, over
every type the nodes use). Padding bytes are zero here (Fast CDR leaves them as they
were in its buffer; no reader looks at them).

:meth:`Codec.decode` (and :meth:`Codec.read`, which also takes other encapsulations
through rclpy and refuses bytes that are not such a message) returns a light object
(``__slots__``) with the message's field names: primitives as Python values, primitive
sequences as read-only numpy arrays viewing the bytes, strings as ``str``, nested
messages as such objects. :meth:`Codec.encode` takes
any object with the field names (such an object, made by :meth:`Codec.new`, or a real
message) and accepts numpy arrays, ``array.array`` or lists for sequences. Types this
module cannot lay out (fixed-size arrays, bounded or wide strings, sequences of messages)
are refused when the codec is made, not guessed.

Why not a library: rosbags' serde (a pinned dependency; a typestore holding the installed
``.msg`` files, ``deserialize_cdr`` / ``serialize_cdr``) writes the same bytes, but it
unpacks field by field into a dataclass and sizes a message before it writes it, so on
the recorded bytes of a run (``python test/measure_cdr.py RUN_DIR`` times both, and
rclpy's own conversion) it reads and writes each ring message slower than this module,
before the dtype coercion and defaults the nodes need. Its ``deserialize_cdr`` also
refuses the bytes of rclpy's ``serialize_message`` when they end in more than 3 unused
bytes (its size estimate). ``mcap_ros2_support_fast`` reads as fast as this module but
writes slower and is GPL-3.0; pycdr2 (Cyclone DDS's IDL layer) is slower still and needs
every type declared again in Python, as does cydr (and a C compiler at run time).
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

#: rosidl basic type -> (struct code, size, numpy dtype)
_BASIC = {
    "boolean": ("?", 1, np.bool_), "octet": ("B", 1, np.uint8), "char": ("B", 1, np.uint8),
    "uint8": ("B", 1, np.uint8), "int8": ("b", 1, np.int8),
    "uint16": ("H", 2, np.dtype("<u2")), "int16": ("h", 2, np.dtype("<i2")),
    "uint32": ("I", 4, np.dtype("<u4")), "int32": ("i", 4, np.dtype("<i4")),
    "uint64": ("Q", 8, np.dtype("<u8")), "int64": ("q", 8, np.dtype("<i8")),
    "float": ("f", 4, np.dtype("<f4")), "double": ("d", 8, np.dtype("<f8")),
}
HEADER = b"\x00\x01\x00\x00"        # encapsulation: CDR, little endian, no options
_EMPTY = {}                         # per dtype: an empty read-only array (a default)


def _empty(dtype) -> np.ndarray:
    a = _EMPTY.get(dtype)
    if a is None:
        a = _EMPTY[dtype] = np.zeros(0, dtype)
        a.flags.writeable = False
    return a


def _message_class(t):
    import importlib
    module = importlib.import_module(".".join(t.namespaces))
    return getattr(module, t.name)


class _Fields:
    """Base of the decoded objects: the fields as attributes, equality by value."""

    __slots__ = ()

    def __eq__(self, other) -> bool:
        if not isinstance(other, type(self)):
            return NotImplemented
        for name in self.__slots__:
            a, b = getattr(self, name), getattr(other, name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not np.array_equal(np.asarray(a), np.asarray(b)):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        inner = ", ".join(f"{n}={getattr(self, n)!r}" for n in self.__slots__)
        return f"{type(self).__name__}({inner})"


class _Layout:
    """Code generation state: the source lines and what is known of the offset.

    ``o`` in the generated code is the offset from the start of the payload; it is known
    statically modulo ``modulus`` (``residue``), so most paddings are constants and runs
    of fixed-size fields become one ``struct`` call."""

    def __init__(self):
        self.lines: list[str] = []
        self.modulus, self.residue = 8, 0       # o = residue (mod modulus)
        self.env: dict[str, Any] = {"np": np, "struct": struct, "_empty": _empty}
        self.count = 0

    def name(self, prefix: str, value=None) -> str:
        self.count += 1
        key = f"_{prefix}{self.count}"
        if value is not None:
            self.env[key] = value
        return key

    def align(self, a: int) -> int | None:
        """Pad to ``a``: the static padding, or None when the caller must emit a runtime
        alignment (the offset is then known modulo ``a``)."""
        if a <= 1:
            return 0
        if a <= self.modulus:
            pad = (-self.residue) % a
            self.residue = (self.residue + pad) % self.modulus
            return pad
        self.modulus, self.residue = a, 0
        return None

    def pad(self, a: int, runtime: str, static: str) -> None:
        """Emit the padding to ``a`` before variable-length data: line ``runtime`` when the
        offset is not known statically, else ``static`` formatted with the constant
        padding (none when it is 0)."""
        pad = self.align(a)
        if pad is None:
            self.lines.append(runtime)
        elif pad:
            self.lines.append(static.format(pad=pad))

    def advance(self, n: int) -> None:
        self.residue = (self.residue + n) % self.modulus

    def unknown(self) -> None:
        """After variable-length data only the alignment emitted before it is known."""
        self.modulus, self.residue = 1, 0


def _members(cls) -> list[tuple[str, Any]]:
    return list(zip(cls.get_fields_and_field_types().keys(), cls.SLOT_TYPES))


def _check_supported(cls, where: str = "") -> None:
    from rosidl_parser import definition as d
    for name, t in _members(cls):
        here = f"{where}{cls.__name__}.{name}"
        if isinstance(t, d.BasicType):
            if t.typename not in _BASIC:
                raise TypeError(f"{here}: basic type {t.typename} not supported")
        elif isinstance(t, d.UnboundedSequence):
            if not isinstance(t.value_type, d.BasicType) or t.value_type.typename not in _BASIC:
                raise TypeError(f"{here}: only sequences of primitives are supported")
        elif isinstance(t, d.UnboundedString):
            pass
        elif isinstance(t, d.NamespacedType):
            _check_supported(_message_class(t), f"{here}/")
        else:
            raise TypeError(f"{here}: {type(t).__name__} not supported")


def _fields_class(cls, classes: dict) -> type:
    """The decoded object's class for message class ``cls`` (made once per type)."""
    key = f"{cls.__module__}.{cls.__name__}"
    if key not in classes:
        names = [n for n, _ in _members(cls)]
        classes[key] = type(cls.__name__, (_Fields,), {"__slots__": tuple(names),
                                                       "__module__": __name__})
    return classes[key]


# ----------------------------------------------------------------------------- reader
def _gen_decode(cls, lay: _Layout, target: str, classes: dict, depth: int = 0) -> None:
    """Lines that fill object ``target`` (already made) from ``b`` at payload offset o."""
    from rosidl_parser import definition as d
    ind = "    "
    run: list[tuple[str, str]] = []          # pending (attribute, struct code) of a run
    fmt = ["<"]

    def flush():
        if not run:
            return
        f = "".join(fmt)
        s = lay.name("S", struct.Struct(f))
        attrs = ", ".join(f"{target}.{a}" for a, _ in run)
        lay.lines.append(f"{ind}{attrs}{',' if len(run) == 1 else ''} = {s}.unpack_from(b, o + 4)")
        lay.lines.append(f"{ind}o += {struct.calcsize(f)}")
        run.clear()
        fmt[:] = ["<"]

    for name, t in _members(cls):
        if isinstance(t, d.BasicType):
            code, size, _ = _BASIC[t.typename]
            pad = lay.align(size)
            if pad is None:
                flush()
                lay.lines.append(f"{ind}o = (o + {size - 1}) & -{size}")
                pad = 0
            fmt.append("x" * pad + code)
            run.append((name, code))
            lay.advance(size)
            continue
        flush()
        if isinstance(t, d.NamespacedType):
            sub = _message_class(t)
            c = lay.name("C", _fields_class(sub, classes))
            obj = f"n{depth}_{lay.count}"
            lay.lines.append(f"{ind}{obj} = {c}.__new__({c})")
            _gen_decode(sub, lay, obj, classes, depth + 1)
            lay.lines.append(f"{ind}{target}.{name} = {obj}")
        elif isinstance(t, d.UnboundedString):
            lay.pad(4, f"{ind}o = (o + 3) & -4", f"{ind}o += {{pad}}")
            lay.lines.append(f"{ind}n, = _U32.unpack_from(b, o + 4)")
            lay.lines.append(f"{ind}{target}.{name} = b[o + 8: o + 7 + n].decode() "
                             f"if n > 1 else ''")
            lay.lines.append(f"{ind}o += 4 + n")
            lay.unknown()
        else:                                    # UnboundedSequence of a basic type
            code, size, dtype = _BASIC[t.value_type.typename]
            lay.pad(4, f"{ind}o = (o + 3) & -4", f"{ind}o += {{pad}}")
            dt = lay.name("D", np.dtype(dtype))
            lay.lines.append(f"{ind}n, = _U32.unpack_from(b, o + 4)")
            lay.lines.append(f"{ind}o += 4")
            lay.lines.append(f"{ind}if n:")
            if size > 1:
                lay.lines.append(f"{ind}    o = (o + {size - 1}) & -{size}")
            lay.lines.append(f"{ind}    {target}.{name} = np.frombuffer(b, {dt}, n, o + 4)")
            lay.lines.append(f"{ind}    o += n * {size}")
            lay.lines.append(f"{ind}else:")
            lay.lines.append(f"{ind}    {target}.{name} = _empty({dt})")
            lay.unknown()
    flush()


# ----------------------------------------------------------------------------- writer
def _gen_encode(cls, lay: _Layout, source: str, depth: int = 0) -> None:
    """Lines that append object ``source``'s fields to bytearray ``out`` (offset
    ``len(out) - 4``)."""
    from rosidl_parser import definition as d
    ind = "    "
    run: list[str] = []
    fmt = ["<"]

    def flush():
        if not run:
            return
        f = "".join(fmt)
        s = lay.name("S", struct.Struct(f))
        lay.lines.append(f"{ind}out += {s}.pack({', '.join(run)})")
        run.clear()
        fmt[:] = ["<"]

    for name, t in _members(cls):
        if isinstance(t, d.BasicType):
            code, size, _ = _BASIC[t.typename]
            pad = lay.align(size)
            if pad is None:
                flush()
                lay.lines.append(f"{ind}out += _ZEROS[: -(len(out) - 4) % {size}]")
                pad = 0
            fmt.append("x" * pad + code)
            run.append(f"{source}.{name}")
            lay.advance(size)
            continue
        flush()
        if isinstance(t, d.NamespacedType):
            obj = f"s{depth}_{lay.count}"
            lay.count += 1
            lay.lines.append(f"{ind}{obj} = {source}.{name}")
            _gen_encode(_message_class(t), lay, obj, depth + 1)
        elif isinstance(t, d.UnboundedString):
            lay.pad(4, f"{ind}out += _ZEROS[: -(len(out) - 4) % 4]",
                    f"{ind}out += _ZEROS[:{{pad}}]")
            lay.lines.append(f"{ind}t = {source}.{name}.encode()")
            lay.lines.append(f"{ind}out += _U32.pack(len(t) + 1)")
            lay.lines.append(f"{ind}out += t")
            lay.lines.append(f"{ind}out += _ZEROS[:1]")
            lay.unknown()
        else:
            code, size, dtype = _BASIC[t.value_type.typename]
            lay.pad(4, f"{ind}out += _ZEROS[: -(len(out) - 4) % 4]",
                    f"{ind}out += _ZEROS[:{{pad}}]")
            dt = lay.name("D", np.dtype(dtype))
            lay.lines.append(f"{ind}v = _seq({source}.{name}, {dt})")
            lay.lines.append(f"{ind}out += _U32.pack(len(v))")
            lay.lines.append(f"{ind}if len(v):")
            if size > 1:
                lay.lines.append(f"{ind}    out += _ZEROS[: -(len(out) - 4) % {size}]")
            lay.lines.append(f"{ind}    out += v.tobytes()")
            lay.unknown()
    flush()


# ----------------------------------------------------------------------------- defaults
def _gen_new(cls, lay: _Layout, target: str, classes: dict, depth: int = 0) -> None:
    """Lines that fill object ``target`` (already made) with the message's defaults."""
    from rosidl_parser import definition as d
    proto = cls()
    for name, t in _members(cls):
        if isinstance(t, d.NamespacedType):
            sub = _message_class(t)
            c = lay.name("C", _fields_class(sub, classes))
            obj = f"n{depth}_{lay.count}"
            lay.lines.append(f"    {obj} = {c}.__new__({c})")
            _gen_new(sub, lay, obj, classes, depth + 1)
            lay.lines.append(f"    {target}.{name} = {obj}")
        elif isinstance(t, d.UnboundedSequence):
            dt = lay.name("D", np.dtype(_BASIC[t.value_type.typename][2]))
            lay.lines.append(f"    {target}.{name} = _empty({dt})")
        else:
            lay.lines.append(f"    {target}.{name} = {getattr(proto, name)!r}")


def _seq(v, dtype) -> np.ndarray:
    """A sequence field as a contiguous array of the wire's dtype (no copy when it is)."""
    if isinstance(v, np.ndarray) and v.dtype == dtype and v.flags.c_contiguous:
        return v
    return np.ascontiguousarray(v, dtype=dtype)


class Codec:
    """Read and write the CDR bytes of one message type (module docstring)."""

    _classes: dict = {}                     # decoded classes, shared by all codecs

    def __init__(self, msg_class):
        _check_supported(msg_class)
        self.msg_class = msg_class
        self.fields_class = _fields_class(msg_class, self._classes)
        lay = _Layout()
        lay.env.update(_U32=struct.Struct("<I"), _C=self.fields_class)
        lay.lines.append("def decode(b):")
        lay.lines.append("    o = 0")
        lay.lines.append("    m = _C.__new__(_C)")
        _gen_decode(msg_class, lay, "m", self._classes)
        lay.lines.append("    return m")
        exec(compile("\n".join(lay.lines), f"<cdr decode {msg_class.__name__}>", "exec"),
             lay.env)
        self.decode = lay.env["decode"]
        self.decode_source = "\n".join(lay.lines)

        lay = _Layout()
        lay.env.update(_U32=struct.Struct("<I"), _ZEROS=bytes(8), _seq=_seq,
                       _HEADER=HEADER)
        lay.lines.append("def encode(m):")
        lay.lines.append("    out = bytearray(_HEADER)")
        _gen_encode(msg_class, lay, "m")
        lay.lines.append("    return bytes(out)")
        exec(compile("\n".join(lay.lines), f"<cdr encode {msg_class.__name__}>", "exec"),
             lay.env)
        self.encode = lay.env["encode"]
        self.encode_source = "\n".join(lay.lines)

        lay = _Layout()
        lay.env.update(_C=self.fields_class)
        lay.lines.append("def new(**fields):")
        lay.lines.append("    m = _C.__new__(_C)")
        _gen_new(msg_class, lay, "m", self._classes)
        lay.lines.append("    for k, v in fields.items():")
        lay.lines.append("        setattr(m, k, v)")
        lay.lines.append("    return m")
        exec(compile("\n".join(lay.lines), f"<cdr new {msg_class.__name__}>", "exec"),
             lay.env)
        #: new(**fields): an object with the message's defaults (nested objects made
        #: afresh), then ``fields``: what :meth:`encode` takes
        self.new = lay.env["new"]

    def read(self, data: bytes):
        """The fields of serialized message ``data``: :meth:`decode` for the little-endian
        CDR that rmw_fastrtps writes on this machine; any other encapsulation (big endian,
        XCDR2, from another host or middleware) is read by rclpy's own deserializer, whose
        message has the same field names. Raises ValueError for bytes that do not hold
        a message of this type."""
        try:
            if data[:2] == HEADER[:2]:
                return self.decode(data)
            from rclpy.serialization import deserialize_message
            return deserialize_message(data, self.msg_class)
        except (struct.error, UnicodeDecodeError, IndexError, ValueError,
                RuntimeError) as exc:           # ValueError: numpy (an array past the
            # end); RuntimeError: rclpy's RMWError (Fast CDR refused the bytes)
            raise ValueError(f"not a {self.msg_class.__name__}: {exc}") from None

    def to_message(self, obj):
        """The rclpy message of ``obj`` (for tools and tests: costs what rclpy costs)."""
        from rclpy.serialization import deserialize_message
        return deserialize_message(self.encode(obj), self.msg_class)


_CODECS: dict = {}


def codec(msg_class) -> Codec:
    """The codec of ``msg_class`` (made once per process)."""
    c = _CODECS.get(msg_class)
    if c is None:
        c = _CODECS[msg_class] = Codec(msg_class)
    return c
