"""Topic and service names of the node graph (a contract: README, Topics and services).

Every node, the recorder, the bag tools and the tests take names from here. Data flows
once around the ring per step (lockstep)::

    maze_sim --OBSERVATION--> sensory_preprocessor --FEATURES--> map_learner
      ^                                                            | SENSORIMOTOR_STATE
      |                                                            v
      +------ACTION------ action_selector <--MOTIVATION-- motivation_estimator
"""

# Per-step data (STEP_QOS in tmgwr_common.node: reliable, keep-last depth 10; lockstep never
# has more than one in flight)
OBSERVATION = "/observation"          # tmgwr_interfaces/msg/Observation, maze_sim
FEATURES = "/features"                # tmgwr_interfaces/msg/Features, sensory_preprocessor
SENSORIMOTOR_STATE = "/sensorimotor_state"  # tmgwr_interfaces/msg/SensorimotorState, map_learner
MOTIVATION = "/motivation"            # tmgwr_interfaces/msg/MotivationField, motivation_estimator
ACTION = "/action"                    # tmgwr_interfaces/msg/Action, action_selector

# Inspection (bounded rate; latched = transient local, depth 1)
MAP = "/map"                          # tmgwr_interfaces/msg/SensorimotorMap, latched
# the whole map as flat arrays (every snapshot_period steps and on request): what a replica
# of /sensorimotor_state's changes starts from after a gap (tmgwr_agent/map_replica.py)
MAP_SNAPSHOT = "/sensorimotor_snapshot"  # tmgwr_interfaces/msg/SensorimotorSnapshot, latched
POTENTIALS = "/potentials"            # tmgwr_interfaces/msg/Potentials (field_period), latched
MAP_MARKERS = "/map_markers"          # visualization_msgs/msg/MarkerArray, latched
GRID = "/maze_grid"                   # nav_msgs/msg/OccupancyGrid, latched
GOAL = "/goal"                        # geometry_msgs/msg/PointStamped (x=col, y=row), latched
AGENT_POSE = "/agent_pose"            # geometry_msgs/msg/PoseStamped
EVENTS = "/maze_events"               # std_msgs/msg/String: goal changes, cell/event changes

# Services
SET_GOAL = "/set_goal"                # tmgwr_interfaces/srv/SetGoal, motivation_estimator
SIM_SET_GOAL = "/maze_sim/set_goal"  # tmgwr_interfaces/srv/SetGoal, maze_sim (validates the cell,
                                      # moves the terminal cell; called by /set_goal)
SET_CELL = "/maze_sim/set_cell"       # tmgwr_interfaces/srv/SetCell
FIRE_EVENT = "/maze_sim/fire_event"   # tmgwr_interfaces/srv/FireEvent
RESET = "/maze_sim/reset"             # std_srvs/srv/Trigger
SAVE_MAP = "/map_learner/save_map"    # tmgwr_interfaces/srv/SaveMap
LOAD_MAP = "/map_learner/load_map"    # tmgwr_interfaces/srv/LoadMap
REQUEST_SNAPSHOT = "/map_learner/request_snapshot"  # std_srvs/srv/Trigger: MAP_SNAPSHOT now
