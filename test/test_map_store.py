"""Safe map persistence (issue 10, item 3): the map learner reads and writes maps by name,
in its own directory, and refuses, saying why and running on, everything else.

Before, "anyone on the domain can write or read any file as the node's user":

* ``save_map`` overwrote a user file, replaced the MCAP being recorded with a map, and
  created directories anywhere;
* ``load_map`` opened ``/etc/shadow``;
* ``load_map`` of a ``.npy`` file, or of a map with out-of-range indices, crashed the
  learner (and that map was saved over the run's own map);
* ``load_map`` of a map with NaN weights was accepted (the map then grew a node per step);
* ``load_map`` of a FIFO hung the learner;
* ``save_map``/``load_map`` of ``~nosuchuser/x.npz`` crashed the learner;
* two graphs in different domains both saved to ``~/.ros/tmgwr_map.npz``; ROS_HOME was
  ignored.

The first part tests :mod:`tmgwr_agent.map_store` on real files (no ROS); the second drives
a running graph (real processes, the recorder writing into the same run directory, as
under ``./tmgwr up``) with the real ``ros2 service call`` where the test is what a user
types, else an rclpy client.
"""

from __future__ import annotations

import os
import re
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from crafted_npz import crafted_npz
from ros_helpers import SERVICE_ANSWERED, allocate_domain, release_domain, ros2_cli, ros2_run
from test_nodes import call

from tmgwr_agent.core.sensorimotor_map import SensorimotorMap
from tmgwr_agent.map_store import (
    FORMAT_KEY,
    MAX_NAME,
    MapStore,
    MapStoreError,
    default_map_dir,
    map_file_name,
    read_map,
    validate_state,
)
from tmgwr_common.checkpoint import CheckpointError, decode

RIGHT, DOWN = np.array([0.0, 1.0]), np.array([1.0, 0.0])


def small_map() -> SensorimotorMap:
    """A real map: four cells walked in a square (four nodes, four links)."""
    m = SensorimotorMap(dim=2, action_dim=2)
    m.step(np.array([0.1, 0.1]), None)
    for x, a in (((0.1, 0.2), RIGHT), ((0.2, 0.2), DOWN), ((0.2, 0.1), -RIGHT),
                 ((0.1, 0.1), -DOWN)):
        m.step(np.array(x), a)
    assert m.size == 4 and m.link_count() == 4
    return m


def arrays(m: SensorimotorMap, **change) -> dict:
    s = {**m.state_dict(), "step_id": np.array(7, dtype=np.int64),
         "run_id": np.array(3, dtype=np.uint64)}
    s.update(change)
    return s


def write_npz(path: Path, state: dict) -> Path:
    with open(path, "wb") as f:
        np.savez(f, **state)
    return path


# =========================================================================== no ROS
@pytest.mark.parametrize("name, why", [
    ("", "empty"),
    ("/etc/shadow", "path separator"),
    ("../x", "path separator"),
    ("..", "'..'"),
    ("a..b", "'..'"),
    (".hidden", "starts with '.'"),
    ("~nosuchuser", "'~'"),
    ("x y", "' '"),
    ("caf\u00e9", "'\u00e9'"),
    ("nul\x00", "'\\x00'"),
    ("x" * (MAX_NAME + 1), f"at most {MAX_NAME}"),
])
def test_a_map_name_that_is_not_a_plain_name_is_refused_saying_why(name, why):
    with pytest.raises(MapStoreError) as exc:
        map_file_name(name)
    assert why in str(exc.value), str(exc.value)


def test_a_plain_name_is_a_file_of_the_store():
    assert map_file_name("map") == "map.npz"
    assert map_file_name("run-2_v1.0") == "run-2_v1.0.npz"
    assert map_file_name("kept.npz") == "kept.npz"
    assert map_file_name("recording_0.mcap") == "recording_0.mcap.npz"   # never the bag


def test_the_default_directory_is_per_graph_under_ros_home(monkeypatch, tmp_path):
    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    assert default_map_dir(7) == tmp_path / "tmgwr" / "domain7"
    assert default_map_dir("7", "/a/b") == tmp_path / "tmgwr" / "domain7_a_b"
    assert default_map_dir(8) != default_map_dir(7) != default_map_dir(7, "/a")
    monkeypatch.delenv("ROS_HOME")
    assert default_map_dir(0) == Path.home() / ".ros" / "tmgwr" / "domain0"


def test_save_and_load_round_trip_with_step_run_and_format_version(tmp_path):
    store = MapStore(tmp_path / "maps")
    m = small_map()
    path = store.save(m, "mine", step_id=41, run_id=9)
    assert path == (tmp_path / "maps" / "mine.npz").resolve()
    with np.load(path) as d:
        assert int(d[FORMAT_KEY]) == 1
    back, step, run = store.load("mine")
    assert (step, run) == (41, 9)
    for k, v in m.state_dict().items():
        assert np.array_equal(back.state_dict()[k], v), k
    # a file SensorimotorMap.save wrote directly (no version member) is format 1
    m.save(tmp_path / "maps" / "direct.npz", 5, 2)
    assert store.load("direct")[1:] == (5, 2)
    # nothing else is left in the directory: no temporary file or directory
    assert sorted(p.name for p in store.directory.iterdir()) == ["direct.npz", "mine.npz"]


def test_save_is_atomic_a_failed_write_leaves_the_old_map(tmp_path):
    store = MapStore(tmp_path)
    store.save(small_map(), "m", 1, 1)
    before = (tmp_path / "m.npz").read_bytes()

    class Failing:
        def save(self, path, step_id, run_id):
            Path(path).write_bytes(b"half a ma")
            raise OSError(28, "No space left on device")

    with pytest.raises(MapStoreError, match="No space left"):
        store.save(Failing(), "m", 2, 1)
    assert (tmp_path / "m.npz").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]


def test_save_never_replaces_a_link_or_a_file_that_is_not_our_map(tmp_path):
    store = MapStore(tmp_path / "run")
    outside = tmp_path / "user_file.txt"
    outside.write_text("precious")
    (store.directory / "link.npz").symlink_to(outside)
    (store.directory / "theirs.npz").write_text("not a map")
    write_npz(store.directory / "arrays.npz", {"x": np.arange(3)})
    os.mkfifo(store.directory / "fifo.npz")
    (store.directory / "dir.npz").mkdir()
    bag = store.directory / "run_0.mcap"
    bag.write_bytes(b"\x89MCAP0\r\n")
    for name, why in (("link", "symbolic link"), ("theirs", "not a tmgwr map"),
                      ("arrays", "not a tmgwr map"), ("fifo", "FIFO"), ("dir", "directory")):
        with pytest.raises(MapStoreError, match=why):
            store.save(small_map(), name)
    assert outside.read_text() == "precious"
    assert (store.directory / "link.npz").is_symlink()
    assert (store.directory / "theirs.npz").read_text() == "not a map"
    store.save(small_map(), "run_0.mcap")                  # the bag's name: another file
    assert bag.read_bytes() == b"\x89MCAP0\r\n"
    assert (store.directory / "run_0.mcap.npz").is_file()
    store.save(small_map(), "kept")
    store.save(small_map(), "kept")                        # our own map: replaced


def test_load_accepts_only_regular_files_and_never_blocks(tmp_path):
    store = MapStore(tmp_path / "run")
    good = store.save(small_map(), "good")
    (store.directory / "shadow.npz").symlink_to("/etc/shadow")
    (store.directory / "alias.npz").symlink_to(good)      # even a link to one of ours
    os.mkfifo(store.directory / "fifo.npz")
    (store.directory / "dir.npz").mkdir()
    cases = {"shadow": "symbolic link", "alias": "symbolic link", "fifo": "FIFO",
             "dir": "directory", "missing": "no such map"}
    for name, why in cases.items():
        t0 = time.monotonic()
        with pytest.raises(MapStoreError, match=why):
            store.load(name)
        assert time.monotonic() - t0 < 5.0, f"{name}: load blocked"
    with pytest.raises(MapStoreError, match="FIFO"):      # a path (initial_map) too
        read_map(store.directory / "fifo.npz")
    with pytest.raises(MapStoreError, match="character device"):
        read_map("/dev/zero")


def test_load_validates_the_whole_content_first(tmp_path):
    store = MapStore(tmp_path)
    m = small_map()
    n, k = m.state_dict()["out"].shape
    np.save(tmp_path / "array.npy", np.arange(10))
    os.replace(tmp_path / "array.npy", tmp_path / "array.npz")       # a .npy, named .npz
    (tmp_path / "text.npz").write_text("hello")
    bad_out = m.state_dict()["out"].copy()
    bad_out[0, 0] = 10 ** 6
    nan_w = m.state_dict()["w"].copy()
    nan_w[1, 0] = np.nan
    obj = np.empty(2, dtype=object)
    cases = {
        "array": ({}, "not an .npz archive"),
        "text": ({}, "not an .npz archive"),
        "out_of_range": (arrays(m, out=bad_out), "link target outside"),
        "nan": (arrays(m, w=nan_w), "not finite"),
        "inf_E": (arrays(m, E=np.full((n, k), np.inf)), "not finite"),
        "E_above_1": (arrays(m, E=np.full((n, k), 2.0)), "outside [0, 1]"),
        "shape": (arrays(m, h=np.ones(n + 1)), "shape"),
        "dtype": (arrays(m, out=m.state_dict()["out"].astype(float)), "array out is float64"),
        "winner": (arrays(m, meta=np.array([1, 0, n + 5])), "winner"),
        "dead_link": (arrays(m, alive=np.zeros(n, dtype=bool)), "dead node"),
        "missing": ({k_: v for k_, v in arrays(m).items() if k_ != "w"}, "no w"),
        "unknown": (arrays(m, extra=np.zeros(1)), "unknown arrays extra"),
        "version": (arrays(m, **{FORMAT_KEY: np.array(2)}), "format version 2"),
        "negative_age": (arrays(m, age=-np.ones((n, k), dtype=np.int64)), "negative"),
        "won_below_1": (arrays(m, won=np.zeros(n)), "samples won below 1"),
    }
    for name, (state, _) in cases.items():
        if state:
            write_npz(tmp_path / f"{name}.npz", state)
    with open(tmp_path / "pickled.npz", "wb") as f:
        np.savez(f, **arrays(m, w=obj))
    cases["pickled"] = ({}, "dtype object (only bool, integers and floats")
    for name, (_, why) in cases.items():
        with pytest.raises(MapStoreError, match=re.escape(why)):
            store.load(name)
    validate_state(arrays(m))                                         # the real one passes


def test_crafted_array_headers_are_refused_before_anything_is_allocated(tmp_path):
    """Issue 24: a 21 kB map whose header declares 10**12 float64 raised MemoryError (the
    learner died). Every header is read first (tmgwr_common.npz_check)."""
    live = arrays(small_map())
    cases = {  # file -> what the refusal says
        crafted_npz(tmp_path / "huge.npz", live, "w"): "member 'w.npy' declares shape "
                                                        "(1000000000000,)",
        crafted_npz(tmp_path / "lie.npz", live, "w", shape=(3, 2), pad=0): "(48 bytes) but holds",
        crafted_npz(tmp_path / "pickle.npz", live, "meta", shape=(3,), descr="|O"):
            "dtype object",
        crafted_npz(tmp_path / "complex.npz", live, "w", descr="<c16"): "dtype complex128",
        crafted_npz(tmp_path / "record.npz", live, "w", descr=[("a", "<f8")]): "dtype",
    }
    with zipfile.ZipFile(tmp_path / "text.npz", "w") as z:
        z.writestr("w.txt", "not an array")
    cases[tmp_path / "text.npz"] = "member 'w.txt' is not an array"
    for path, why in cases.items():
        assert path.stat().st_size < 25_000
        with pytest.raises(MapStoreError, match=re.escape(why)) as info:
            read_map(path)
        assert str(path) in str(info.value) and "refused" in str(info.value)
    # a checkpoint goes through the same reader
    with pytest.raises(CheckpointError, match=r"declares shape \(1000000000000,\)"):
        decode((tmp_path / "huge.npz").read_bytes(), "maze_sim.ckpt.npz")


def test_one_directory_one_learner(tmp_path):
    a = MapStore(tmp_path)
    a.lock()
    b = MapStore(tmp_path)
    with pytest.raises(MapStoreError, match=f"in use by another map_learner \\(pid {os.getpid()}"):
        b.lock()
    a.close()
    b.lock()
    b.close()


def test_a_directory_that_cannot_be_made_is_refused_saying_why(tmp_path):
    with pytest.raises(MapStoreError, match="nosuchuser"):
        MapStore("~nosuchuser/maps")
    (tmp_path / "file").write_text("x")
    with pytest.raises(MapStoreError, match="map directory"):
        MapStore(tmp_path / "file" / "maps")


# =========================================================================== the graph
SAVE, LOAD = "/map_learner/save_map", "/map_learner/load_map"


def service_call(domain: int, service: str, srv_type: str, request: str) -> tuple[bool, str]:
    """What a user types: ``ros2 service call SERVICE TYPE REQUEST``; (success, message)."""
    p = ros2_cli("service", "call", service, srv_type, request, domain=domain)
    with p:
        out = p.wait(timeout=60, done=SERVICE_ANSWERED)
    m = re.search(r"success=(True|False), message=(['\"])(.*)\2(, path=|\)$)", out, re.M)
    assert m, p.describe("no response")
    return m[1] == "True", m[3]


def learner_step(domain: int, run_dir: Path) -> int:
    """The step the learner is at: save map 'probe' (rclpy client) and read its step id."""
    [res] = call(domain, [[SAVE, "SaveMap", {"name": "probe"}]])
    assert res["success"], res
    with np.load(run_dir / "probe.npz") as d:
        return int(d["step_id"])


def assert_running_and_stepping(graph) -> None:
    domain, run_dir, procs = graph
    dead = [n for n, p in procs.items() if not p.running()]
    assert not dead, procs[dead[0]].describe(f"{dead[0]} died")
    first = learner_step(domain, run_dir)
    t0 = time.monotonic()
    while learner_step(domain, run_dir) <= first:
        assert time.monotonic() - t0 < 30, procs["maze_sim"].describe("the ring stopped")
        time.sleep(0.5)


@pytest.fixture(scope="module")
def graph(tmp_path_factory):
    """The recorder and the five nodes in one run directory, as ``./tmgwr up`` lays them
    out (graph_specs: recorder output_dir = map_dir = the run directory)."""
    from tmgwr_agent.graph.supervisor import graph_specs
    domain = allocate_domain()
    run_dir = tmp_path_factory.mktemp("runs") / "20990101T000000Z"
    procs = {}
    try:
        for spec in graph_specs(seed=1, goal="2", record_dir=run_dir):
            cmd = spec.command()
            procs[spec.label] = ros2_run(spec.package, spec.executable, *cmd[1:],
                                         domain=domain)
        for p in procs.values():
            p.wait_for_line("ready|recording", timeout=90)
        # the tests ask about names, not about an empty map: wait for the first learnt
        # step (a save before it is refused with "the map is empty", whatever the name)
        t0 = time.monotonic()
        while not call(domain, [[SAVE, "SaveMap", {"name": "probe"}]])[0]["success"]:
            assert time.monotonic() - t0 < 60, procs["maze_sim"].describe("no step yet")
            time.sleep(0.5)
        yield domain, run_dir, procs
    finally:
        for p in reversed(list(procs.values())):
            p.stop()
        release_domain(domain)


@pytest.mark.ros
@pytest.mark.timeout(240)
def test_save_map_writes_only_named_maps_in_the_run_directory(graph):
    domain, run_dir, procs = graph
    outside = run_dir.parent / "user_file.txt"
    outside.write_text("precious")
    (run_dir / "link.npz").symlink_to(outside)
    (run_dir / "notes.npz").write_text("a user's file")
    [bag] = run_dir.glob("*.mcap")
    cases = {  # what a user types -> what the refusal says
        str(outside): "path separator",
        str(run_dir.parent / "newdir" / "sub" / "m.npz"): "path separator",
        "../escape": "path separator",
        "~nosuchuser/x.npz": "path separator",
        "link": "symbolic link",
        "notes": "not a tmgwr map",
    }
    for name, why in cases.items():
        ok, message = service_call(domain, SAVE, "tmgwr_interfaces/srv/SaveMap",
                                   f"{{name: '{name}'}}")
        assert not ok and why in message, (name, message)
    assert outside.read_text() == "precious"
    assert (run_dir / "notes.npz").read_text() == "a user's file"
    assert not (run_dir.parent / "newdir").exists()
    # the bag being recorded is never the target: its name gives another file
    size = bag.stat().st_size
    ok, message = service_call(domain, SAVE, "tmgwr_interfaces/srv/SaveMap",
                               f"{{name: '{bag.name}'}}")
    assert ok and message.endswith(f"{bag.name}.npz"), message
    assert bag.stat().st_size >= size and bag.read_bytes()[:5] == b"\x89MCAP"
    ok, message = service_call(domain, SAVE, "tmgwr_interfaces/srv/SaveMap", "{name: ''}")
    assert ok and message.endswith(str(run_dir / "map.npz")), message
    assert_running_and_stepping(graph)


@pytest.mark.ros
@pytest.mark.timeout(240)
def test_load_map_reads_only_regular_map_files_of_its_directory(graph):
    domain, run_dir, procs = graph
    (run_dir / "shadow.npz").symlink_to("/etc/shadow")
    os.mkfifo(run_dir / "fifo.npz")
    for name, why in {"/etc/shadow": "path separator", "~nosuchuser/x.npz": "path separator",
                      "shadow": "symbolic link", "fifo": "FIFO", "absent": "no such map"
                      }.items():
        t0 = time.monotonic()
        ok, message = service_call(domain, LOAD, "tmgwr_interfaces/srv/LoadMap",
                                   f"{{name: '{name}'}}")
        assert not ok and why in message, (name, message)
        assert time.monotonic() - t0 < 30
    assert_running_and_stepping(graph)


@pytest.mark.ros
@pytest.mark.timeout(240)
def test_load_map_validates_before_replacing_the_live_map(graph):
    domain, run_dir, procs = graph
    step = learner_step(domain, run_dir)
    with np.load(run_dir / "probe.npz") as d:
        live = {k: d[k] for k in d.files if k != FORMAT_KEY}
    np.save(run_dir / "array.npy", np.arange(10))
    os.replace(run_dir / "array.npy", run_dir / "array.npz")
    bad_out = live["out"].copy()
    bad_out[0, 0] = 10 ** 6
    write_npz(run_dir / "out_of_range.npz", {**live, "out": bad_out})
    nan_w = live["w"].copy()
    nan_w[:, 0] = np.nan
    write_npz(run_dir / "nan.npz", {**live, "w": nan_w})
    write_npz(run_dir / "three_d.npz", {**live, "w": np.zeros((len(live["w"]), 3)),
                                        "c": np.zeros((len(live["c"]), 3))})
    res = call(domain, [[LOAD, "LoadMap", {"name": name}]
                        for name in ("array", "out_of_range", "nan", "three_d")])
    whys = ("not an .npz archive", "link target outside", "not finite", "dimension 3/2")
    for r, why in zip(res, whys):
        assert not r["success"] and why in r["message"], (why, r)
    assert_running_and_stepping(graph)
    # the live map was never replaced: the run's own map is saved whole and valid
    [r] = call(domain, [[SAVE, "SaveMap", {"name": ""}]])
    assert r["success"], r
    m, saved_step, _ = read_map(run_dir / "map.npz")
    # (the live map learns on meanwhile, so its size may differ from the probe's: what a
    # refused load would have left is a 3-d, NaN or out-of-range map, checked here)
    assert saved_step > step and m.size > 50, (saved_step, step, m.size)
    assert m.w.shape[1] == 2 and np.isfinite(m.w[: m.n][m.alive[: m.n]]).all()
    # and a valid map is loaded
    [r] = call(domain, [[LOAD, "LoadMap", {"name": "probe"}]])
    assert r["success"] and "probe.npz" in r["message"], r
    assert_running_and_stepping(graph)


@pytest.mark.ros
@pytest.mark.timeout(240)
def test_load_map_of_a_crafted_header_is_refused_and_the_graph_steps_on(graph):
    """Issue 24: this file killed the learner (MemoryError) and with it the graph."""
    domain, run_dir, procs = graph
    with np.load(run_dir / "probe.npz") as d:
        live = {k: d[k] for k in d.files}
    crafted_npz(run_dir / "huge.npz", live, "w")
    ok, message = service_call(domain, LOAD, "tmgwr_interfaces/srv/LoadMap", "{name: 'huge'}")
    assert not ok and str(run_dir / "huge.npz") in message, message
    assert "declares shape (1000000000000,)" in message, message
    assert_running_and_stepping(graph)


def start_learner(domain, *args, env=None):
    return ros2_run("tmgwr_agent", "map_learner", "--ros-args", *args, domain=domain,
                    env=env)


@pytest.mark.ros
@pytest.mark.timeout(180)
def test_two_graphs_keep_their_own_maps_under_ros_home(ros_domain, tmp_path):
    """Two learners in two domains with the same ROS_HOME save to two files; a second
    learner of the same graph (domain and namespace) is refused, not allowed to share."""
    small_map().save(tmp_path / "start.npz", 10, 1)
    env = {"ROS_HOME": str(tmp_path / "ros_home")}
    other = allocate_domain()
    try:
        a = start_learner(ros_domain, "-p", f"initial_map:={tmp_path / 'start.npz'}", env=env)
        b = start_learner(other, "-p", f"initial_map:={tmp_path / 'start.npz'}", env=env)
        with a, b:
            a.wait_for_line("map_learner ready", timeout=60)
            b.wait_for_line("map_learner ready", timeout=60)
            twin = start_learner(ros_domain, env=env)
            with twin:
                out = twin.wait(timeout=60, check=False)
            assert twin.proc.returncode == 2 and "in use by another map_learner" in out, out
            assert "Traceback" not in out
            for p in (a, b):
                p.stop()
                assert p.proc.returncode == 0, p.describe("did not stop cleanly")
    finally:
        release_domain(other)
    home = tmp_path / "ros_home" / "tmgwr"
    for d in (ros_domain, other):
        assert (home / f"domain{d}" / "map.npz").is_file(), list(home.rglob("*"))
        assert f"to {home / f'domain{d}' / 'map.npz'}" in (a if d == ros_domain else b).output


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_a_bad_initial_map_stops_the_learner_at_start_saying_why(ros_domain, tmp_path):
    os.mkfifo(tmp_path / "fifo.npz")
    m = small_map()
    nan_w = m.state_dict()["w"].copy()
    nan_w[0, 0] = np.nan
    write_npz(tmp_path / "nan.npz", arrays(m, w=nan_w))
    crafted_npz(tmp_path / "huge.npz", arrays(m), "w")      # issue 24: exit 2, no reason
    cases = {"~nosuchuser/x.npz": "nosuchuser", str(tmp_path / "fifo.npz"): "FIFO",
             str(tmp_path / "nan.npz"): "not finite", "nosuchmap": "no such map",
             str(tmp_path / "huge.npz"): "declares shape (1000000000000,)"}
    procs = {k: start_learner(ros_domain, "-p", f"initial_map:={k}", "-p",
                              f"map_dir:={tmp_path / 'maps'}" + str(i))
             for i, k in enumerate(cases)}
    for k, p in procs.items():
        with p:
            out = p.wait(timeout=60, check=False)
        assert p.proc.returncode == 2 and "cannot start" in out and cases[k] in out, out
        assert "Traceback" not in out, out


def test_keep_previous_renames_an_earlier_runs_map_and_nothing_else(tmp_path):
    """Issue 24: each fresh start in a domain overwrote the previous run's map.npz."""
    store = MapStore(tmp_path)
    try:
        assert store.keep_previous("map") is None                  # nothing to keep
        store.save(small_map(), "map", 7, 1)
        os.utime(tmp_path / "map.npz", (0, 0))                     # 1970-01-01T00:00:00Z
        kept = store.keep_previous("map")
        assert kept == tmp_path / "map.19700101T000000Z.npz" and kept.is_file()
        assert not (tmp_path / "map.npz").exists()
        assert store.load("map.19700101T000000Z")[1] == 7          # the same map
        store.save(small_map(), "map", 9, 2)
        os.utime(tmp_path / "map.npz", (0, 0))                     # same stamp: a suffix
        assert store.keep_previous("map") == tmp_path / "map.19700101T000000Z-2.npz"
        (tmp_path / "map.npz").write_text("not a map")             # someone else's file
        assert store.keep_previous("map") is None
        assert (tmp_path / "map.npz").read_text() == "not a map"
    finally:
        store.close()


@pytest.mark.ros
@pytest.mark.timeout(180)
def test_a_fresh_learner_keeps_the_previous_runs_map(ros_domain, tmp_path):
    """Two fresh learners, one after the other, in one domain (the default map_dir): the
    first one's map.npz is kept under its time stamp, the second saves its own."""
    small_map().save(tmp_path / "start10.npz", 10, 1)
    small_map().save(tmp_path / "start20.npz", 20, 2)
    env = {"ROS_HOME": str(tmp_path / "ros_home")}
    home = tmp_path / "ros_home" / "tmgwr" / f"domain{ros_domain}"
    first = start_learner(ros_domain, "-p", f"initial_map:={tmp_path / 'start10.npz'}", env=env)
    with first:
        first.wait_for_line("map_learner ready", timeout=60)
        first.stop()
    assert first.proc.returncode == 0 and read_map(home / "map.npz")[1] == 10, first.output
    second = start_learner(ros_domain, "-p", f"initial_map:={tmp_path / 'start20.npz'}",
                           env=env)
    with second:
        line = second.wait_for_line(r"an earlier run's map .* kept as (map\.\S+\.npz)", 60)
        second.stop()
    assert second.proc.returncode == 0, second.output
    kept = re.search(r"kept as (map\.\S+\.npz)", line)[1]
    assert read_map(home / kept)[1] == 10, second.output            # the first run's map
    assert read_map(home / "map.npz")[1] == 20, second.output       # the second run's own
