"""maze_sim: the grid world of the paper's experiments (ROS-free) and its ROS 2 node."""

from maze_sim.maze import ACTION_VECTORS, ACTIONS, N_ACTIONS, Maze, MazeError, bfs_distances, move
from maze_sim.world import GridWorld, StepInfo

__all__ = ["ACTIONS", "ACTION_VECTORS", "N_ACTIONS", "Maze", "MazeError", "GridWorld",
           "StepInfo", "bfs_distances", "move"]
