"""Small mazes shared by the core, baseline and experiment tests.

CORRIDOR: S at (1, 1), G at (1, 5), a corridor of 5 cells.
SMALL: shortest S->G path 10 steps, along the left column and the bottom row. Event ``a``
blocks (5, 3) on it, leaving the 14-step detour over the top. Goals 1 (1, 7), 2 (5, 1).
"""

CORRIDOR = "#######\n#S...G#\n#######\n"

SMALL = ("#########\n"
         "#S..#..1#\n"
         "#.#.#.#.#\n"
         "#.#...#.#\n"
         "#.#####.#\n"
         "#2.a...G#\n"
         "#########\n")
