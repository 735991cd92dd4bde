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

When any node exits, the launch ends: with exit code 0 when it finished (maze_sim's
``exit_when_done``), else non-zero, saying which node exited with which code and its last
error line (e.g. ``maze_sim exited with code 2: [maze_sim] cannot start: ...``). Ctrl-C
stops every node. The launch file sets no DDS setting (``ROS_DOMAIN_ID``,
``ROS_AUTOMATIC_DISCOVERY_RANGE``, ``ROS_STATIC_PEERS``, ``RMW_IMPLEMENTATION``, Fast DDS
profiles): the nodes inherit the user's environment (docs/graph.md, DDS settings).

The pip-only environment has no ``launch`` package (not on PyPI): there ``./tmgwr up``
does the same with tmgwr_agent.graph.supervisor.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, RegisterEventHandler, Shutdown
from launch.conditions import IfCondition
from launch.event_handlers import OnProcessExit, OnProcessIO
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import LifecycleNode, Node

# the graph in data-flow order and the nodes that keep a checkpoint: one place, shared
# with ./tmgwr up (the names are a contract)
from tmgwr_agent.graph.supervisor import CHECKPOINTED, GRAPH_NODES

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
    """Ends the launch when any node exits: a clean finish (exit code 0) shuts it down, any
    other exit raises :class:`NodeExited`, which ``ros2 launch`` reports as 'Caught
    exception in launch ...: maze_sim exited with code 2: <its last error line>' and turns
    into exit code 1. Exits during a shutdown (Ctrl-C, another node's exit) are expected."""

    def __init__(self):
        self.last_line: dict[str, str] = {}

    def on_output(self, event) -> None:
        lines = [ln.strip() for ln in event.text.decode(errors="replace").splitlines()]
        lines = [ln for ln in lines if ln]
        if lines:
            self.last_line[event.process_name] = lines[-1]

    def on_exit(self, event, context):
        if context.is_shutdown:
            return None
        name = event.process_name.rsplit("-", 1)[0]          # maze_sim-2 -> maze_sim
        code = event.returncode
        if code == 0:
            return [Shutdown(reason=f"{name} finished (exit code 0)")]
        why = self.last_line.get(event.process_name, "no output")
        raise NodeExited(f"{name} exited with code {code}: {why}")

    def handlers(self):
        return [RegisterEventHandler(OnProcessIO(on_stderr=self.on_output)),
                RegisterEventHandler(OnProcessExit(on_exit=self.on_exit))]


def graph_nodes(context):
    """The five nodes, each with the user's parameter file (if any), then its overrides."""
    params_file = LaunchConfiguration("params_file").perform(context)
    files = [params_file] if params_file else []
    namespace = LaunchConfiguration("namespace")
    seed = int_argument(context, "seed")
    world = {"world": LaunchConfiguration("world")}   # the simulator's and the agent's senses
    overrides = {
        "maze_sim": {"maze": LaunchConfiguration("maze"), "goal": LaunchConfiguration("goal"),
                     "seed": seed, **world},
        "action_selector": {"seed": seed, **world},
        "map_learner": dict(world),
        "motivation_estimator": dict(world),
    }
    resume_dir = LaunchConfiguration("resume").perform(context).strip()
    if resume_dir:               # continue from the checkpoints there (docs/graph.md, Continuing)
        import os
        run_dir = os.path.abspath(os.path.expanduser(resume_dir))
        if not os.path.isdir(run_dir):
            raise ValueError(f"launch argument resume:={resume_dir}: no such directory")
        for name in CHECKPOINTED:
            overrides.setdefault(name, {}).update(checkpoint_dir=run_dir, resume=True)
        overrides["map_learner"]["map_dir"] = run_dir
    if not true_argument(context, "autostart"):   # the learner waits for `ros2 lifecycle set`
        overrides.setdefault("map_learner", {})["autostart"] = False
    if true_argument(context, "composed"):
        # one process, one executor (tmgwr_agent composed): its parameters reach every node
        # of it, a name only the nodes that declare it (maze and goal: maze_sim)
        shared = {**overrides["maze_sim"], **overrides["action_selector"],
                  **overrides["map_learner"]}
        return [Node(package="tmgwr_agent", executable="composed", output="screen",
                     namespace=namespace, parameters=[*files, shared])]
    return [
        (LifecycleNode if executable in MANAGED else Node)(
            package=package, executable=executable, name=executable, output="screen",
            namespace=namespace, parameters=[*files, overrides.get(executable, {})])
        for package, executable in GRAPH_NODES
    ]


def generate_launch_description():
    arguments = [
        DeclareLaunchArgument("maze", default_value="paper_13x17.txt",
                              description="maze file: a path, or a file name in "
                                          "share/maze_sim/mazes"),
        DeclareLaunchArgument("world", default_value="grid",
                              description="the world maze_sim hosts, built from the maze "
                                          "(grid, pointmaze: MuJoCo's PointMaze); the agent "
                                          "nodes take its senses"),
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
    ]
    recorder = Node(
        package="tmgwr_agent", executable="recorder", name="recorder", output="screen",
        namespace=LaunchConfiguration("namespace"),
        parameters=[{"output_dir": LaunchConfiguration("output_dir")}],
        condition=IfCondition(LaunchConfiguration("record")))
    return LaunchDescription(arguments + ExitWatch().handlers()
                             + [recorder, OpaqueFunction(function=graph_nodes)])
