"""The ROS 2 nodes of the graph (docs/graph.md, Topics and services): thin shells around the core.

One module per node; :mod:`tmgwr_common.node` holds what they share (QoS, parameters, flat
arrays, ``main``). Each per-step callback calls the same core objects, in the same order,
as :meth:`tmgwr_agent.core.agent.TMGWRAgent.step` does in-process
(:mod:`tmgwr_agent.experiments.lockstep` is that loop, the graph's in-process twin).

One lockstep step goes once around the ring (names in :mod:`tmgwr_common.topics`)::

    maze_sim            --/observation (Observation)------------> sensory_preprocessor
    sensory_preprocessor --/features (Features)-----------------> map_learner
    map_learner          --/sensorimotor_state (SensorimotorState: winner + this
                           step's map as flat arrays)-----------> motivation_estimator
    motivation_estimator --/motivation (MotivationField: V + the winner's links)
                                                       ---------> action_selector
    action_selector      --/action (Action, NONE after a terminal observation)
                                                       ---------> maze_sim

Every per-step message carries the ``run_id`` and ``step_id`` of its observation; the
simulator steps only on the action for its current step of its run and resends the
observation when none comes (``resend_period``); every node answers a step it already
handled with its cached output, so a resend never changes what is learnt, and follows a
newer run (a restarted simulator) from its first step (:mod:`tmgwr_common.lockstep`).

Inspection and control (names at the root namespace: topics are relative and the nodes'
services private, so under ``__ns:=/a`` each is prefixed with ``/a``):

=====================  ==================================  ==========================
name                   type                                by / QoS
=====================  ==================================  ==========================
/maze_grid             nav_msgs/OccupancyGrid              maze_sim, latched
/goal                  geometry_msgs/PointStamped          maze_sim, latched
/agent_pose            geometry_msgs/PoseStamped           maze_sim, best effort
/maze_events           std_msgs/String                     maze_sim, latched (last)
/map                   tmgwr_interfaces/SensorimotorMap    map_learner, latched
/map_markers           visualization_msgs/MarkerArray      map_learner, latched
/set_goal              tmgwr_interfaces/srv/SetGoal        motivation_estimator
/maze_sim/set_goal     tmgwr_interfaces/srv/SetGoal        maze_sim (used by /set_goal)
/maze_sim/set_cell     tmgwr_interfaces/srv/SetCell        maze_sim
/maze_sim/fire_event   tmgwr_interfaces/srv/FireEvent      maze_sim
/maze_sim/reset        std_srvs/srv/Trigger                maze_sim
/map_learner/save_map  tmgwr_interfaces/srv/SaveMap        map_learner
/map_learner/load_map  tmgwr_interfaces/srv/LoadMap        map_learner
=====================  ==================================  ==========================

Coordinates: cell (row, col) is the point x = col, y = row in frame ``maze``.
Parameters: every core hyperparameter (a field of the core's config dataclasses, where its
default lives) is a read-only ROS parameter of the node that uses it, with its range in the
descriptor; ``--params-file FILE`` (ROS layout, ``/**`` or per-node sections, overrides
only) and ``-p name:=value`` both work; an invalid value, or a name no node of the graph
declares, stops the node at start (exit code 2) naming the parameter. ``TMGWR_EXECUTOR``
(``events`` default, or ``single``) picks the executor.
"""

# First, before any node module imports numpy, rclpy or numba: in a node's own process this
# installs its stop request (a Ctrl-C while the node still starts is a clean stop).
import tmgwr_common.stop  # noqa: E402, F401
