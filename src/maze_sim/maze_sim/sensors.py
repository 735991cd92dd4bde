"""How the agent senses the maze: ``--sensor SPEC`` as Gymnasium observation wrappers.

The bare :class:`~maze_sim.gym_env.MazeEnv` senses the (row, col) of the agent's cell.
A sensor spec changes that, as comma-joined parts (``noise=0.1,scale=1:2,rotate=30``):

* ``noise=SIGMA``: Gaussian noise of standard deviation SIGMA *cells* on each sensed
  coordinate, drawn afresh for every observation (:class:`NoiseSensor`);
* ``scale=SX:SY``: the two sensed axes in other units, ``(SX row, SY col)``
  (:class:`ScaleSensor`);
* ``rotate=DEG``: the sensed vector rotated by DEG degrees counter-clockwise,
  ``(row, col) -> (cos row - sin col, sin row + cos col)`` (:class:`RotateSensor`);
* ``view=K``: instead of a position, a local view (:class:`LocalViewSensor`): the
  (2K+1) x (2K+1) window of cells around the agent, row-major, 1.0 for a wall (the
  outside of the maze counts as wall) and 0.0 for a free cell, followed by a *compass*:
  the unit vector (d_row, d_col) from the agent's cell towards the goal cell, (0, 0) at the
  goal. ``view`` takes no other part.

Composition order (fixed, whatever the order of the parts in the spec): noise, then scale,
then rotate, i.e. ``obs = R(DEG) diag(SX, SY) ((row, col) + noise)``. Noise comes first so
that SIGMA is in cells, as the issue states it.

Why a compass and not a heading: the agent's goal is a sensation (the goal cell as sensed),
and a heading would make that sensation depend on which way the agent happened to face
when it arrived; the compass is defined by the cell alone, so the goal sensation is one
vector (the goal's window with compass (0, 0)) and a goal change changes what is sensed
everywhere, as it changes the task. It tells the agent the goal's direction, not its
distance: windows far apart that look alike and point the same way stay aliased.

The goal sensation goes through the same wrappers without noise
(:func:`goal_sensation`), so the agent's goal is in its own sensor space.

A spec is checked by :func:`parse_sensor`, which raises :class:`SensorSpecError` naming
the part that is wrong; :attr:`SensorSpec.text` is its normalised string (``"identity"``
for none), the form recorded in the experiments' JSON.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium
import numpy as np
from gymnasium import spaces

from maze_sim.maze import Cell

IDENTITY = "identity"
KEYS = ("noise", "scale", "rotate", "view")
MAX_VIEW = 5                     # a window of at most 11 x 11 cells

#: As in :mod:`maze_sim.gym_env`: with noise the observation box is widened by this many
#: standard deviations on each side and observations are clipped to it.
NOISE_BOUND_SIGMAS = 6.0


class SensorSpecError(ValueError):
    """A ``--sensor`` spec that cannot be read; the message names the part."""


@dataclass(frozen=True)
class SensorSpec:
    """A checked sensor spec: every transform at its identity value when absent."""

    noise: float = 0.0
    scale: tuple[float, float] = (1.0, 1.0)
    rotate: float = 0.0          # degrees, in [0, 360)
    view: int = 0                # 0 = no local view (a position is sensed)

    @property
    def identity(self) -> bool:
        return self == SensorSpec()

    @property
    def text(self) -> str:
        """The normalised spec: parts in composition order, identity parts left out."""
        if self.view:
            return f"view={self.view}"
        parts = []
        if self.noise:
            parts.append(f"noise={self.noise:g}")
        if self.scale != (1.0, 1.0):
            parts.append(f"scale={self.scale[0]:g}:{self.scale[1]:g}")
        if self.rotate:
            parts.append(f"rotate={self.rotate:g}")
        return ",".join(parts) or IDENTITY

    def linear_map(self) -> np.ndarray:
        """``M = R(rotate) diag(scale)``: noise-free sensation = M (row, col)."""
        return rotation(self.rotate) @ np.diag(self.scale)

    @property
    def dim(self) -> int:
        """Dimension of the sensation."""
        return (2 * self.view + 1) ** 2 + 2 if self.view else 2


def rotation(deg: float) -> np.ndarray:
    """The 2-D rotation by ``deg`` degrees; exact for multiples of 90 degrees."""
    quarter = {0.0: (1.0, 0.0), 90.0: (0.0, 1.0), 180.0: (-1.0, 0.0), 270.0: (0.0, -1.0)}
    c, s = quarter.get(deg % 360.0, (math.cos(math.radians(deg)),
                                     math.sin(math.radians(deg))))
    return np.array([[c, -s], [s, c]])


def _number(part: str, value: str) -> float:
    try:
        x = float(value)
    except ValueError:
        raise SensorSpecError(f"sensor part {part!r}: {value!r} is not a number") from None
    if not math.isfinite(x):
        raise SensorSpecError(f"sensor part {part!r}: {value!r} is not finite")
    return x


def parse_sensor(spec: str | None) -> SensorSpec:
    """Read ``--sensor SPEC``; ``None``, ``""``, ``"none"`` and ``"identity"`` are the
    identity. Raises :class:`SensorSpecError` naming the part that is wrong."""
    text = (spec or "").strip()
    if text.lower() in ("", "none", IDENTITY):
        return SensorSpec()
    values: dict = {}
    for part in (p.strip() for p in text.split(",")):
        if not part:
            raise SensorSpecError(f"empty part in sensor spec {text!r}")
        key, eq, value = part.partition("=")
        key = key.strip()
        if not eq:
            raise SensorSpecError(f"sensor part {part!r}: expected KEY=VALUE with KEY one "
                                  f"of {', '.join(KEYS)}")
        if key not in KEYS:
            raise SensorSpecError(f"sensor part {part!r}: unknown key {key!r} "
                                  f"(keys: {', '.join(KEYS)})")
        if key in values:
            raise SensorSpecError(f"sensor part {part!r}: {key} given twice")
        value = value.strip()
        if key == "noise":
            sigma = _number(part, value)
            if sigma < 0:
                raise SensorSpecError(f"sensor part {part!r}: sigma must be >= 0")
            values[key] = sigma
        elif key == "scale":
            xy = value.split(":")
            if len(xy) != 2:
                raise SensorSpecError(f"sensor part {part!r}: expected scale=SX:SY")
            sx, sy = (_number(part, v) for v in xy)
            if sx <= 0 or sy <= 0:
                raise SensorSpecError(f"sensor part {part!r}: SX and SY must be > 0")
            values[key] = (sx, sy)
        elif key == "rotate":
            values[key] = _number(part, value) % 360.0
        else:
            k = _number(part, value)
            if k != int(k) or not 1 <= k <= MAX_VIEW:
                raise SensorSpecError(f"sensor part {part!r}: K must be an integer in "
                                      f"1..{MAX_VIEW}")
            values[key] = int(k)
    if "view" in values and len(values) > 1:
        others = ", ".join(k for k in values if k != "view")
        raise SensorSpecError(f"sensor part 'view={values['view']}' takes no other part "
                              f"(got {others} too)")
    return SensorSpec(**values)


# ------------------------------------------------------------------ the wrappers
class PositionSensor(gymnasium.ObservationWrapper):
    """Base of the wrappers over a sensed 2-D position: ``observation`` = ``sense(obs)``
    (with noise where the wrapper adds any), ``sense_goal`` the same without noise."""

    def observation(self, observation: np.ndarray) -> np.ndarray:
        return self.sense(np.asarray(observation, dtype=np.float64))

    def sense(self, obs: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def sense_goal(self, obs: np.ndarray, goal: Cell) -> np.ndarray:
        return self.sense(obs)


def _linear_box(box: spaces.Box, M: np.ndarray) -> spaces.Box:
    """The bounding box of ``M x`` for ``x`` in ``box`` (a linear map of a 2-D box)."""
    corners = np.array([[a, b] for a in (box.low[0], box.high[0])
                        for b in (box.low[1], box.high[1])]) @ M.T
    return spaces.Box(corners.min(axis=0), corners.max(axis=0), dtype=np.float64)


class NoiseSensor(PositionSensor):
    """Adds N(0, sigma^2) to each coordinate of every observation (sigma in the units of
    the wrapped sensation: cells over the bare env). ``rng``: the generator of the noise
    (default: the env's ``np_random``, seeded by ``reset(seed=...)``). The box is widened
    by :data:`NOISE_BOUND_SIGMAS` sigma and observations are clipped to it."""

    def __init__(self, env: gymnasium.Env, sigma: float,
                 rng: np.random.Generator | None = None):
        super().__init__(env)
        if not math.isfinite(sigma) or sigma < 0:
            raise ValueError(f"noise sigma must be finite and >= 0, got {sigma}")
        self.sigma = float(sigma)
        self.rng = rng
        inner = env.observation_space
        margin = NOISE_BOUND_SIGMAS * self.sigma
        self.observation_space = spaces.Box(inner.low - margin, inner.high + margin,
                                            dtype=np.float64)

    def sense(self, obs: np.ndarray) -> np.ndarray:
        rng = self.rng if self.rng is not None else self.np_random
        noisy = obs + rng.normal(0.0, self.sigma, size=obs.shape)
        return np.clip(noisy, self.observation_space.low, self.observation_space.high)

    def sense_goal(self, obs: np.ndarray, goal: Cell) -> np.ndarray:
        return obs


class LinearSensor(PositionSensor):
    """``obs -> M obs`` for a fixed 2 x 2 matrix ``M``."""

    def __init__(self, env: gymnasium.Env, M: np.ndarray):
        super().__init__(env)
        self.M = np.asarray(M, dtype=np.float64)
        self.observation_space = _linear_box(env.observation_space, self.M)

    def sense(self, obs: np.ndarray) -> np.ndarray:
        return np.clip(self.M @ obs, self.observation_space.low, self.observation_space.high)


class ScaleSensor(LinearSensor):
    """``(row, col) -> (SX row, SY col)``: the axes sensed in other units."""

    def __init__(self, env: gymnasium.Env, sx: float, sy: float):
        super().__init__(env, np.diag([float(sx), float(sy)]))


class RotateSensor(LinearSensor):
    """The sensed vector rotated by ``deg`` degrees (:func:`rotation`)."""

    def __init__(self, env: gymnasium.Env, deg: float):
        super().__init__(env, rotation(deg))


class LocalViewSensor(PositionSensor):
    """The (2K+1) x (2K+1) window of walls around the agent plus the compass to the goal
    (module docstring). It reads the world's current walls, cell and goal (it is the
    sensor), not the wrapped observation."""

    def __init__(self, env: gymnasium.Env, k: int):
        super().__init__(env)
        if not 1 <= int(k) <= MAX_VIEW:
            raise ValueError(f"view K must be in 1..{MAX_VIEW}, got {k}")
        self.k = int(k)
        n = (2 * self.k + 1) ** 2
        self.observation_space = spaces.Box(
            np.concatenate([np.zeros(n), [-1.0, -1.0]]),
            np.concatenate([np.ones(n), [1.0, 1.0]]), dtype=np.float64)

    def view_at(self, cell: Cell) -> np.ndarray:
        world = self.env.unwrapped.world
        walls, k = world.walls, self.k
        rows, cols = walls.shape
        padded = np.ones((rows + 2 * k, cols + 2 * k))
        padded[k:k + rows, k:k + cols] = walls
        r, c = cell
        window = padded[r:r + 2 * k + 1, c:c + 2 * k + 1].ravel()
        d = np.array(world.goal, dtype=np.float64) - np.array(cell, dtype=np.float64)
        norm = float(np.hypot(d[0], d[1]))
        compass = d / norm if norm > 0 else np.zeros(2)
        return np.concatenate([window, compass])

    def sense(self, obs: np.ndarray) -> np.ndarray:
        return self.view_at(self.env.unwrapped.world.cell)

    def sense_goal(self, obs: np.ndarray, goal: Cell) -> np.ndarray:
        return self.view_at(goal)


def wrap(env: gymnasium.Env, spec: SensorSpec | str | None,
         rng: np.random.Generator | None = None) -> gymnasium.Env:
    """``env`` (a :class:`~maze_sim.gym_env.MazeEnv`) under the sensor ``spec``, wrappers
    in the order noise, scale, rotate (or the view alone); ``rng`` drives the noise
    (default: the env's ``np_random``). The identity returns ``env`` itself."""
    spec = spec if isinstance(spec, SensorSpec) else parse_sensor(spec)
    if spec.view:
        return LocalViewSensor(env, spec.view)
    if spec.noise:
        env = NoiseSensor(env, spec.noise, rng)
    if spec.scale != (1.0, 1.0):
        env = ScaleSensor(env, *spec.scale)
    if spec.rotate:
        env = RotateSensor(env, spec.rotate)
    return env


def chain(env: gymnasium.Env) -> list[PositionSensor]:
    """The sensor wrappers of ``env``, innermost first."""
    out = []
    while isinstance(env, gymnasium.Wrapper):
        if isinstance(env, PositionSensor):
            out.append(env)
        env = env.env
    return out[::-1]


def sense(env: gymnasium.Env, raw: np.ndarray) -> np.ndarray:
    """What the sensor wrappers of ``env`` make of the bare env's observation ``raw``:
    the same functions ``env.step`` applies, for a loop that steps the world itself."""
    obs = np.asarray(raw, dtype=np.float64)
    for w in chain(env):
        obs = w.sense(obs)
    return obs


def goal_sensation(env: gymnasium.Env, goal: Cell) -> np.ndarray:
    """The noise-free sensation at ``goal``: what the agent is asked to reach, in its own
    sensor space."""
    obs = np.array(goal, dtype=np.float64)
    for w in chain(env):
        obs = w.sense_goal(obs, goal)
    return obs
