"""Launch the node graph on a ROS 2 Jazzy install (Fig. 1a; docs/graph.md).

    ros2 launch tmgwr_agent agent.launch.py
    ros2 launch tmgwr_agent agent.launch.py maze:=paper_13x17.txt goal:=2 seed:=1 record:=true
    ros2 launch tmgwr_agent agent.launch.py composed:=true     # one process, one executor
    ros2 launch tmgwr_agent agent.launch.py resume:=runs/20250101T000000Z  # continue a run
    ros2 launch tmgwr_agent agent.launch.py autostart:=false   # then: ros2 lifecycle set

Starts ``maze_sim`` and the four agent nodes (and, with ``record:=true``, the MCAP
recorder first). Every hyperparameter defaults to its spec (the config dataclasses of the
core); ``params_file:=FILE`` passes a ROS 2 parameter file of overrides to the five nodes
(``/**: ros__parameters: {gamma: 0.9}`` or per-node sections). Then, from another shell::

    ros2 service call /set_goal tmgwr_interfaces/srv/SetGoal "{goal: {x: 11.0, y: 1.0, z: 0.0}}"
    ros2 service call /maze_sim/fire_event tmgwr_interfaces/srv/FireEvent "{event: a}"

``map_learner`` is a managed (lifecycle) node, started as a launch_ros ``LifecycleNode``:
with ``autostart:=true`` (the default) it configures and activates itself, so the graph
steps at once; with ``autostart:=false`` it waits unconfigured (the ring waits with it)
until ``ros2 lifecycle set /map_learner configure`` and ``... activate``, or a ChangeState
event of a launch file that includes this one (ros2/demos ``lifecycle_py`` style).

``namespace:=a`` puts every node (and the recorder) in ``/a``: topics and services are
relative or private, so two agents run side by side in one domain (``/a/set_goal``,
``/a/maze_sim/fire_event``, ...).

A fresh launch keeps its maps and checkpoints in a directory of its own,
``$ROS_HOME/tmgwr/domain<ID>[_<ns>]/launch_<UTC stamp>/`` (logged at start; a later launch
never overwrites them; ``resume:=`` that directory continues the run).

A node that dies while the graph runs (a crash, SIGKILL) is started again after
``respawn_delay`` seconds (launch's ``respawn``) and continues from its checkpoint in that
directory. A node that dies more than ``respawn_limit`` times within ``respawn_window``
seconds ends the launch (exit code 1) naming it: ``map_learner died 6 times within 60 s
(the limit is 5), last exit code -9: <its last error line>``; ``respawn_limit:=0`` ends it at
the first death. A node that exits before its ready line (a start-up error) or with
code 0 (maze_sim's ``exit_when_done``, a lifecycle ``shutdown`` of the learner) is not
started again: the launch ends, with exit code 0 when the node finished cleanly, else
non-zero, saying which node exited with which code and its last error line (e.g.
``maze_sim exited with code 2: [maze_sim] cannot start: ...``). The recorder is started
again only with ``output_dir:=''`` (each start writes its own ``runs/<stamp>/``). Ctrl-C
stops every node. The launch file sets no DDS setting (``ROS_DOMAIN_ID``,
``ROS_AUTOMATIC_DISCOVERY_RANGE``, ``ROS_STATIC_PEERS``, ``RMW_IMPLEMENTATION``, Fast DDS
profiles): the nodes inherit the user's environment (docs/graph.md, DDS settings).

The pip-only environment has no ``launch`` package (not on PyPI): there ``./tmgwr up``
does the same with tmgwr_agent.graph.supervisor.
"""

from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    Shutdown,
)
from launch.event_handlers import OnProcessExit, OnProcessIO
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

# the graph in data-flow order, the nodes that keep a checkpoint, the ready lines and the
# respawn policy: one place, shared with ./tmgwr up (the names are a contract)
from tmgwr_agent.graph.respawn import RESPAWN_DELAY, RESPAWN_MAX_DEATHS, RESPAWN_WINDOW
from tmgwr_agent.graph.supervisor import CHECKPOINTED, GRAPH_NODES, READY, RECORDER_READY

#: The managed (lifecycle) nodes: started as launch_ros LifecycleNode actions, so a launch
#: file that includes this one can send them ChangeState events and watch OnStateTransition.
MANAGED = ("map_learner",)


def int_argument(context, name: str) -> int:
    """A launch argument that must be an integer >= 0; the error names it (``ros2 launch``
    prints it as 'Caught exception in launch ...: launch argument seed:=abc: ...')."""
    text = LaunchConfiguration(name).perform(context)
    try:
        value = int(text.strip())
    except ValueError:
        value = -1
    if value < 0:
        raise ValueError(f"launch argument {name}:={text}: expected an integer >= 0")
    return value


def true_argument(context, name: str) -> bool:
    return LaunchConfiguration(name).perform(context).strip().lower() in ("true", "1")


class NodeExited(RuntimeError):
    """A node exited while the graph ran (``ros2 launch`` prints the message and exits 1)."""


class ExitWatch:
    """Ends the launch when a node exits for good: a clean finish (exit code 0) shuts it
    down; an exit before the node's ready line (a start-up error), or the death more than
    ``limit`` times within ``window`` seconds of a node that launch respawns, raises
    :class:`NodeExited`, which ``ros2 launch`` reports as 'Caught exception in launch ...:
    maze_sim exited with code 2: <its last error line>' and turns into exit code 1. Other
    deaths are left to launch's ``respawn``. Exits during a shutdown (Ctrl-C, another node's
    exit) are expected."""

    def __init__(self, limit: int = RESPAWN_MAX_DEATHS, window: float = RESPAWN_WINDOW):
        self.limit, self.window = limit, window
        self.last_line: dict[str, str] = {}
        self.ready: set[str] = set()              # process names that printed a ready line
        self.deaths: dict[str, list[float]] = {}
        self.respawned: set[str] = set()          # node names launch respawns
        self.shutdown_sent = False                # a Shutdown is on its way

    def on_output(self, event) -> None:
        lines = [ln.strip() for ln in event.text.decode(errors="replace").splitlines()]
        lines = [ln for ln in lines if ln]
        if lines:
            self.last_line[event.process_name] = lines[-1]
        if any(READY.search(ln) or RECORDER_READY.search(ln) for ln in lines):
            self.ready.add(event.process_name)

    def on_exit(self, event, context):
        import time
        if context.is_shutdown or self.shutdown_sent:
            return None
        name = event.process_name.rsplit("-", 1)[0]          # maze_sim-2 -> maze_sim
        code = event.returncode
        if code == 0:
            # once: a terminal's Ctrl-C stops every node at once, and a second Shutdown
            # queued before the first is handled made launch_ros shut its ROS adapter
            # twice ('Cannot shutdown a ROS adapter that is not running', exit code 1)
            self.shutdown_sent = True
            return [Shutdown(reason=f"{name} finished (exit code 0)")]
        why = self.last_line.get(event.process_name, "no output")
        if event.process_name not in self.ready or name not in self.respawned:
            raise NodeExited(f"{name} exited with code {code}: {why}")
        now = time.monotonic()
        times = [t for t in self.deaths.get(name, []) if now - t <= self.window]
        times.append(now)
        self.deaths[name] = times
        if len(times) > self.limit:
            raise NodeExited(f"{name} died {len(times)} times within {self.window:g} s (the "
                             f"limit is {self.limit}), last exit code {code}: {why}")
        return None                               # launch's respawn starts it again

    def handlers(self):
        return [RegisterEventHandler(OnProcessIO(on_stderr=self.on_output)),
                RegisterEventHandler(OnProcessExit(on_exit=self.on_exit))]


def float_argument(context, name: str) -> float:
    text = LaunchConfiguration(name).perform(context)
    try:
        value = float(text.strip())
    except ValueError:
        value = -1.0
    if not value >= 0:
        raise ValueError(f"launch argument {name}:={text}: expected a number >= 0")
    return value


def launch_run_dir(context) -> str:
    """The directory of this launch's maps and checkpoints: ``resume:=DIR``, else a new
    ``launch_<UTC stamp>`` in the graph's directory (a later launch never overwrites it)."""
    import os
    from datetime import datetime, timezone

    from tmgwr_common.checkpoint import graph_dir
    resume_dir = LaunchConfiguration("resume").perform(context).strip()
    if resume_dir:               # continue from the checkpoints there (docs/graph.md, Continuing)
        run_dir = os.path.abspath(os.path.expanduser(resume_dir))
        if not os.path.isdir(run_dir):
            raise ValueError(f"launch argument resume:={resume_dir}: no such directory")
        return run_dir
    base = graph_dir(namespace="/" + LaunchConfiguration("namespace").perform(context))
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    run_dir, n = base / f"launch_{stamp}", 1
    while run_dir.exists():
        n += 1
        run_dir = base / f"launch_{stamp}-{n}"
    run_dir.mkdir(parents=True)
    return str(run_dir)


def graph_nodes(context, watch: ExitWatch):
    """The recorder (``record:=true``) and the five nodes, each with the user's parameter
    file (if any), then its overrides; every node that keeps a checkpoint resumes from the
    launch's directory, so a respawned one continues where it was."""
    params_file = LaunchConfiguration("params_file").perform(context)
    files = [params_file] if params_file else []
    namespace = LaunchConfiguration("namespace")
    seed = int_argument(context, "seed")
    watch.limit = int_argument(context, "respawn_limit")
    watch.window = float_argument(context, "respawn_window")
    respawn = {"respawn": watch.limit > 0,
               "respawn_delay": float_argument(context, "respawn_delay")}
    world = {"world": LaunchConfiguration("world")}   # the simulator's and the agent's senses
    overrides = {
        "maze_sim": {"maze": LaunchConfiguration("maze"), "goal": LaunchConfiguration("goal"),
                     "seed": seed, **world},
        "action_selector": {"seed": seed, **world},
        "sensory_preprocessor": dict(world),
        "map_learner": dict(world),
        "motivation_estimator": dict(world),
    }
    run_dir = launch_run_dir(context)
    for name in CHECKPOINTED:
        overrides.setdefault(name, {}).update(checkpoint_dir=run_dir, resume=True)
    overrides["map_learner"]["map_dir"] = run_dir
    if not true_argument(context, "autostart"):   # the learner waits for `ros2 lifecycle set`
        overrides.setdefault("map_learner", {})["autostart"] = False
    actions = [LogInfo(msg=f"tmgwr: maps and checkpoints in {run_dir} (continue this run: "
                           f"resume:={run_dir})")]
    if true_argument(context, "record"):
        # the ring's first step waits until the recorder has matched every ring publisher
        overrides["maze_sim"]["await_recorder"] = True
        output_dir = LaunchConfiguration("output_dir").perform(context)
        again = {**respawn, "respawn": respawn["respawn"] and not output_dir}
        actions.append(Node(package="tmgwr_agent", executable="recorder", name="recorder",
                            output="screen", namespace=namespace,
                            parameters=[{"output_dir": output_dir}], **again))
        if again["respawn"]:
            watch.respawned.add("recorder")
    if true_argument(context, "composed"):
        # one process, one executor (tmgwr_agent composed): its parameters reach every node
        # of it, a name only the nodes that declare it (maze and goal: maze_sim)
        shared = {k: v for node in overrides.values() for k, v in node.items()}
        if respawn["respawn"]:
            watch.respawned.add("composed")
        return actions + [Node(package="tmgwr_agent", executable="composed", output="screen",
                               namespace=namespace, parameters=[*files, shared], **respawn)]
    if respawn["respawn"]:
        watch.respawned.update(executable for _, executable in GRAPH_NODES)
    return actions + [
        (LifecycleNode if executable in MANAGED else Node)(
            package=package, executable=executable, name=executable, output="screen",
            namespace=namespace, parameters=[*files, overrides.get(executable, {})], **respawn)
        for package, executable in GRAPH_NODES
    ]


def ctrl_c_through_launch_only() -> None:
    """Let a Ctrl-C reach ``ros2 launch`` only through launch's own signal handling.

    launch handles SIGINT through a wakeup fd (launch.utilities.AsyncSafeSignalManager),
    yet it leaves Python's default handler in place, which raises KeyboardInterrupt at
    whatever bytecode the main thread runs. launch catches it around its loop, but one
    raised inside asyncio's own code breaks the loop's state: inside ``loop.create_task``
    it destroys a task ('Task was destroyed but it is pending!', and launch exits 1), and
    between a queue's wakeup and the waiting task it loses the wakeup, so launch never
    handles its Shutdown and hangs. A terminal's Ctrl-C reaches launch and every node at
    once, and a second Ctrl-C is common. With a Python handler that does nothing, the
    signal still reaches launch through the wakeup fd, and no exception is raised."""
    import signal
    import threading

    if (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        signal.signal(signal.SIGINT, lambda signum, frame: None)


def generate_launch_description():
    ctrl_c_through_launch_only()
    arguments = [
        DeclareLaunchArgument("maze", default_value="paper_13x17.txt",
                              description="maze file: a path, or a file name in "
                                          "share/maze_sim/mazes"),
        DeclareLaunchArgument("world", default_value="grid",
                              description="the world maze_sim hosts, built from the maze "
                                          "(grid, minigrid, pointmaze: MuJoCo's "
                                          "PointMaze); the agent nodes take its senses"),
        DeclareLaunchArgument("goal", default_value="G",
                              description="initial goal: a goal name ('G', '1'-'9') or 'row,col'"),
        DeclareLaunchArgument("seed", default_value="0",
                              description="seed of the simulator and the exploration policy"),
        DeclareLaunchArgument("record", default_value="false",
                              description="record every topic to MCAP (tmgwr_agent recorder)"),
        DeclareLaunchArgument("output_dir", default_value="",
                              description="recorder bag directory ('' = runs/<UTC timestamp>/)"),
        DeclareLaunchArgument("composed", default_value="false",
                              description="run the five nodes in one process on one "
                                          "executor (tmgwr_agent composed)"),
        DeclareLaunchArgument("resume", default_value="",
                              description="continue the run whose checkpoints are in this "
                                          "directory (a ./tmgwr up run directory, or "
                                          "$ROS_HOME/tmgwr/domain<ID>); '' = start fresh"),
        DeclareLaunchArgument("autostart", default_value="true",
                              description="the map learner (a lifecycle node) configures "
                                          "and activates itself; false: it waits "
                                          "unconfigured for `ros2 lifecycle set`"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="ROS namespace of every node ('' = the root): "
                                          "two graphs in one domain need two namespaces"),
        DeclareLaunchArgument("params_file", default_value="",
                              description="ROS 2 parameter file of overrides for the five "
                                          "nodes ('' = every parameter at its default)"),
        DeclareLaunchArgument("respawn_limit", default_value=str(RESPAWN_MAX_DEATHS),
                              description="a node that dies is started again from its "
                                          "checkpoint; more deaths of one node than this "
                                          "within respawn_window end the launch (0: the "
                                          "first death does)"),
        DeclareLaunchArgument("respawn_window", default_value=f"{RESPAWN_WINDOW:g}",
                              description="seconds over which a node's deaths are counted"),
        DeclareLaunchArgument("respawn_delay", default_value=f"{RESPAWN_DELAY:g}",
                              description="seconds from a node's death to its restart"),
    ]
    watch = ExitWatch()
    return LaunchDescription(arguments + watch.handlers()
                             + [OpaqueFunction(function=graph_nodes, args=[watch])])
