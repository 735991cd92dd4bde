"""maze_sim: the grid world of the paper's experiments (ROS-free) and its ROS 2 node."""

# First, before numpy and rclpy: in the node's own process this installs its stop request
# (a Ctrl-C while the node still starts is a clean stop; elsewhere it does nothing).
import tmgwr_common.stop  # noqa: F401

# isort: split
from maze_sim.maze import ACTION_VECTORS, ACTIONS, N_ACTIONS, Maze, MazeError, bfs_distances, move
from maze_sim.world import GridWorld, StepInfo

__all__ = ["ACTIONS", "ACTION_VECTORS", "N_ACTIONS", "Maze", "MazeError", "GridWorld",
           "StepInfo", "bfs_distances", "move"]
