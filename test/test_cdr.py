"""tmgwr_common.cdr against rclpy's own serialization, for every message the nodes read or
write with it: what it writes, rclpy reads back as the same message; what rclpy writes, it
reads back as the same values (so both lay the fields out alike).
Random contents, with the sequences empty or not and strings of every length modulo 8 (so
every field meets every alignment)."""

from __future__ import annotations

import array
from pathlib import Path

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosidl_parser import definition as d

from tmgwr_common.cdr import Codec, codec
from tmgwr_interfaces.msg import (
    Action,
    Features,
    MotivationField,
    Observation,
    SensorimotorSnapshot,
    SensorimotorState,
)

TYPES = (Observation, Features, SensorimotorState, MotivationField, Action,
         SensorimotorSnapshot)

LIMITS = {"int8": (-128, 127), "uint8": (0, 255), "int16": (-2 ** 15, 2 ** 15 - 1),
          "uint16": (0, 2 ** 16 - 1), "int32": (-2 ** 31, 2 ** 31 - 1),
          "uint32": (0, 2 ** 32 - 1), "int64": (-2 ** 63, 2 ** 63 - 1),
          "uint64": (0, 2 ** 64 - 1), "octet": (0, 255), "char": (0, 255)}
TYPECODES = {"double": "d", "float": "f", "int32": "i", "uint32": "I", "uint8": "B",
             "int8": "b", "int16": "h", "uint16": "H", "int64": "q", "uint64": "Q",
             "octet": "B"}


def value(t: str, rng: np.random.Generator):
    if t == "boolean":
        return bool(rng.integers(2))
    if t in ("double", "float"):
        v = float(rng.choice([0.0, -0.0, 1.5, -3.25, 1e300, 5e-324, np.inf]))
        return v if t == "double" or abs(v) < 1e30 else 2.5
    lo, hi = LIMITS[t]
    return [lo, hi, 0, 1, lo + int(rng.random() * (hi - lo))][int(rng.integers(5))]


def fill(msg, rng: np.random.Generator):
    """Random values in every field of rclpy message ``msg`` (nested ones too)."""
    for (name, _), t in zip(msg.get_fields_and_field_types().items(), msg.SLOT_TYPES):
        if isinstance(t, d.NamespacedType):
            fill(getattr(msg, name), rng)
        elif isinstance(t, d.UnboundedString):
            setattr(msg, name, "maze"[: int(rng.integers(5))] + "x" * int(rng.integers(8)))
        elif isinstance(t, d.UnboundedSequence):
            vt = t.value_type.typename
            n = int(rng.choice([0, 0, 1, 2, 3, 7]))
            items = [value(vt, rng) for _ in range(n)]
            setattr(msg, name, array.array(TYPECODES[vt], items))
        else:
            setattr(msg, name, value(t.typename, rng))
    return msg


def same(decoded, msg) -> bool:
    """A decoded object equals rclpy message ``msg`` field by field (floats bit for bit)."""
    for name in msg.get_fields_and_field_types():
        a, b = getattr(decoded, name), getattr(msg, name)
        if hasattr(b, "get_fields_and_field_types"):
            if not same(a, b):
                return False
        elif isinstance(b, array.array):
            if not (isinstance(a, np.ndarray) and a.tobytes() == b.tobytes()):
                return False
        elif isinstance(b, float):
            if np.float64(a).tobytes() != np.float64(b).tobytes():
                return False
        elif a != b or type(a) is not type(b):
            return False
    return True


def rosbags_typestore():
    """rosbags' typestore holding the installed ``.msg`` files of std_msgs and
    tmgwr_interfaces (a second CDR implementation, independent of rclpy's and ours)."""
    from ament_index_python.packages import get_package_share_directory
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    store, types = get_typestore(Stores.EMPTY), {}      # EMPTY: builtin Time, Duration
    for pkg in ("std_msgs", "tmgwr_interfaces"):
        for path in sorted((Path(get_package_share_directory(pkg)) / "msg").glob("*.msg")):
            types.update(get_types_from_msg(path.read_text(), f"{pkg}/msg/{path.stem}"))
    store.register(types)
    return store


@pytest.mark.parametrize("msg_type", TYPES, ids=lambda t: t.__name__)
def test_codec_reads_and_writes_what_rclpy_does(msg_type):
    c = codec(msg_type)
    rng = np.random.default_rng(abs(hash(msg_type.__name__)) % 2 ** 32)
    for _ in range(300):
        msg = fill(msg_type(), rng)
        data = serialize_message(msg)
        decoded = c.decode(data)
        assert same(decoded, msg), (msg, decoded)
        written = c.encode(decoded)
        assert deserialize_message(written, msg_type) == msg
        assert same(c.decode(written), msg)
        # rmw_fastrtps sizes the buffer by its estimate of the serialized size, which can
        # leave unused bytes after the last field (none are written here)
        assert len(written) <= len(data)
        assert written[:4] == data[:4]                  # encapsulation header
    default = c.new()                                   # the message's defaults
    assert deserialize_message(c.encode(default), msg_type) == msg_type()


@pytest.mark.parametrize("msg_type", TYPES, ids=lambda t: t.__name__)
def test_rosbags_serde_reads_what_it_writes_and_writes_the_same_bytes(msg_type):
    """rosbags' serde (test/measure_cdr.py: not used by the nodes, slower) as a second
    oracle: it reads our bytes, and writing what it read gives our bytes exactly."""
    store, c = rosbags_typestore(), codec(msg_type)
    name = f"tmgwr_interfaces/msg/{msg_type.__name__}"
    rng = np.random.default_rng(abs(hash(msg_type.__name__ + "rosbags")) % 2 ** 32)
    for _ in range(100):
        msg = fill(msg_type(), rng)
        written = c.encode(c.decode(serialize_message(msg)))
        theirs = store.deserialize_cdr(written, name)
        assert bytes(store.serialize_cdr(theirs, name)) == written, msg


def test_encode_takes_numpy_arrays_of_other_dtypes_and_plain_lists():
    c = codec(MotivationField)
    m = c.new(run_id=3, step_id=4, winner_link_targets=np.array([5, -1], dtype=np.int64),
              winner_link_potentials=[0.5, 0.25],
              winner_link_reliability=np.arange(4.0)[::2])     # not contiguous
    back = deserialize_message(c.encode(m), MotivationField)
    assert list(back.winner_link_targets) == [5, -1]
    assert list(back.winner_link_potentials) == [0.5, 0.25]
    assert list(back.winner_link_reliability) == [0.0, 2.0]
    assert c.new().winner_link_targets is not m.winner_link_targets or \
        len(c.new().winner_link_targets) == 0


def test_decoded_arrays_view_the_bytes_read_only():
    c = codec(Features)
    f = Features()
    f.features = array.array("d", [1.0, 2.0])
    decoded = c.decode(serialize_message(f))
    assert decoded.features.tolist() == [1.0, 2.0]
    with pytest.raises(ValueError):
        decoded.features[0] = 5.0


def test_types_it_cannot_lay_out_are_refused_when_the_codec_is_made():
    from visualization_msgs.msg import MarkerArray

    from tmgwr_interfaces.msg import SensorimotorMap
    for t in (MarkerArray, SensorimotorMap):            # sequences of messages
        with pytest.raises(TypeError, match="sequences of primitives"):
            Codec(t)


def test_bytes_that_are_not_the_message_are_dropped_and_the_node_runs_on():
    from tmgwr_common.node import decoded
    got, said = [], []
    handler = decoded(Features, got.append, said.append)
    f = Features()
    f.features = array.array("d", [1.0, 2.0])
    data = serialize_message(f)
    handler(data[:30])                          # cut short
    handler(b"\x00\x01")                        # the encapsulation alone
    assert got == [] and len(said) == 1 and "not a Features" in said[0]   # said once / 10 s
    handler(b"\x00\x00" + data[2:])             # says big endian: rclpy reads it, refuses
    assert got == []
    handler(data)
    assert len(got) == 1 and got[0].features.tolist() == [1.0, 2.0]
    assert codec(Features).read(data).features.tolist() == [1.0, 2.0]
    with pytest.raises(ValueError, match="not a Features"):
        codec(Features).read(b"\x00\x00" + data[2:])
