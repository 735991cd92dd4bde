"""Topic and service names of the node graph (a contract: docs/graph.md, Topics and services).

Every node, the recorder, the bag tools and the tests take names from here. Data flows
once around the ring per step (lockstep)::

    maze_sim --OBSERVATION--> sensory_preprocessor --FEATURES--> map_learner
      ^                                                            | SENSORIMOTOR_STATE
      |                                                            v
      +------ACTION------ action_selector <--MOTIVATION-- motivation_estimator

Names follow the ROS conventions: topics and the graph's own ``set_goal`` service are
*relative* (resolved in the node's namespace: ``observation`` is ``/observation`` at the
root and ``/a/observation`` under ``__ns:=/a`` or ``ros2 launch ... namespace:=a``), and a
node's own services are *private* (``~/set_cell`` of maze_sim is ``/maze_sim/set_cell``,
``/a/maze_sim/set_cell`` under ``/a``). So two graphs run side by side in one domain, each
in its namespace; at the root namespace every name is what it always was.
"""

# Per-step data (STEP_QOS in tmgwr_common.node: reliable, keep-last STEP_DEPTH; lockstep
# never has more than one in flight)
OBSERVATION = "observation"           # tmgwr_interfaces/msg/Observation, maze_sim
FEATURES = "features"                 # tmgwr_interfaces/msg/Features, sensory_preprocessor
SENSORIMOTOR_STATE = "sensorimotor_state"   # tmgwr_interfaces/msg/SensorimotorState, map_learner
MOTIVATION = "motivation"             # tmgwr_interfaces/msg/MotivationField, motivation_estimator
ACTION = "action"                     # tmgwr_interfaces/msg/Action, action_selector

# Inspection (bounded rate; latched = transient local, depth 1)
MAP = "map"                           # tmgwr_interfaces/msg/SensorimotorMap, latched
# the whole map as flat arrays (every snapshot_period steps and on request): what a replica
# of sensorimotor_state's changes starts from after a gap (tmgwr_agent/map_replica.py)
MAP_SNAPSHOT = "sensorimotor_snapshot"  # tmgwr_interfaces/msg/SensorimotorSnapshot, latched
POTENTIALS = "potentials"             # tmgwr_interfaces/msg/Potentials (field_period), latched
MAP_MARKERS = "map_markers"           # visualization_msgs/msg/MarkerArray, latched
GRID = "maze_grid"                    # nav_msgs/msg/OccupancyGrid, latched
GOAL = "goal"                         # geometry_msgs/msg/PointStamped (x=col, y=row), latched
AGENT_POSE = "agent_pose"             # geometry_msgs/msg/PoseStamped
EVENTS = "maze_events"                # std_msgs/msg/String: goal changes, cell/event changes
# What the world declares of its sensor (goal region, sensor's range), latched: maze_sim's in
# sensation units, sensory_preprocessor's in feature units (the motivation estimator's input)
WORLD_SENSES = "world_senses"         # tmgwr_interfaces/msg/SensorInfo, maze_sim, latched
FEATURE_SENSES = "feature_senses"     # tmgwr_interfaces/msg/SensorInfo, preprocessor, latched
# The recorder's word that it has matched a publisher on every per-step topic it records (the
# bag's directory), latched: a simulator told to wait for it (maze_sim's await_recorder) starts
# the ring only then, so step 0 is in the bag on every topic (docs/graph.md, Recording)
RECORDER_READY = "recorder_ready"     # std_msgs/msg/String, recorder, latched
# The recorder's word that it has recorded a message of this run (run_id) on every per-step
# topic it records; 0: it records none of them. Latched. A reader matched to a publisher is
# no proof that the publisher has matched the reader (discovery runs on both sides, each
# at its own pace), a recorded message is: maze_sim's await_recorder holds its run's first
# step, resending it, until the recorder says so (docs/graph.md, Recording)
RECORDER_RUN = "recorder_run"         # std_msgs/msg/UInt64, recorder, latched

# Services: the graph's goal (relative), then the nodes' own (private, "~/": node/name)
SET_GOAL = "set_goal"                 # tmgwr_interfaces/srv/SetGoal, maze_sim (the graph's)
SIM_SET_GOAL = "~/set_goal"           # tmgwr_interfaces/srv/SetGoal, maze_sim (the same)
SET_CELL = "~/set_cell"               # tmgwr_interfaces/srv/SetCell, maze_sim
FIRE_EVENT = "~/fire_event"           # tmgwr_interfaces/srv/FireEvent, maze_sim
RESET = "~/reset"                     # std_srvs/srv/Trigger, maze_sim
SAVE_MAP = "~/save_map"               # tmgwr_interfaces/srv/SaveMap, map_learner
LOAD_MAP = "~/load_map"               # tmgwr_interfaces/srv/LoadMap, map_learner
REQUEST_SNAPSHOT = "~/request_snapshot"  # std_srvs/srv/Trigger, map_learner: MAP_SNAPSHOT now

SIMULATOR, LEARNER = "maze_sim", "map_learner"     # the node names that own those services

#: The per-step topics of the ring, in data-flow order.
STEP_TOPICS = (OBSERVATION, FEATURES, SENSORIMOTOR_STATE, MOTIVATION, ACTION)


def of_node(node: str, name: str) -> str:
    """A private name (``~/x``) of ``node`` as another node of the same namespace calls it
    (relative: ``node/x``); any other name is returned as it is."""
    return f"{node}/{name[2:]}" if name.startswith("~/") else name


def qualified(name: str, namespace: str = "/", node: str = "") -> str:
    """The fully qualified name of a relative (or, with ``node``, private) name in
    ``namespace``: ``qualified("observation", "a")`` is ``/a/observation``,
    ``qualified(SET_CELL, "/a", SIMULATOR)`` is ``/a/maze_sim/set_cell``."""
    name = of_node(node, name) if node else name
    if name.startswith("/"):
        return name
    ns = "/" + "/".join(p for p in namespace.split("/") if p)
    return (ns.rstrip("/") + "/" + name) if ns != "/" else "/" + name


TOPIC_KEYS = ("OBSERVATION", "FEATURES", "SENSORIMOTOR_STATE", "MOTIVATION", "ACTION", "MAP",
              "MAP_SNAPSHOT", "POTENTIALS", "MAP_MARKERS", "GRID", "GOAL", "AGENT_POSE",
              "EVENTS", "WORLD_SENSES", "FEATURE_SENSES")


class GraphNames:
    """The graph's topic names fully qualified in ``namespace``, as ``ros2 topic list`` and a
    bag show them (``/observation`` at the root, ``/a/observation`` under ``namespace:=a``):
    ``GraphNames("a").OBSERVATION``."""

    def __init__(self, namespace: str = "/"):
        self.namespace = "/" + namespace.strip("/")
        for key in TOPIC_KEYS:
            setattr(self, key, qualified(globals()[key], namespace))

    @classmethod
    def of_bag(cls, names) -> "GraphNames":
        """The names of the graph a recording holds: the namespace of its one observation
        topic (the root when there are none or several)."""
        suffix = "/" + OBSERVATION
        found = sorted({n[: -len(suffix)] or "/" for n in names if n.endswith(suffix)})
        return cls(found[0] if len(found) == 1 else "/")
