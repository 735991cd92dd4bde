"""The TMGWR-based agent (Fig. 1a): preprocessor -> sensorimotor map -> motivation
estimator -> action selector, one step at a time.

Each step: the sensation reached by the last action is preprocessed, presented to the
TMGWR map with the action vector that produced it (growth, adaptation, Eq. 1-2 on the
link between the previous and the current winner), the motivation potentials are
re-solved (Eq. 4-5 with the value of the unknown, Eq. 5', warm-started), and the action
selector picks the next action (Eq. 6 over the winner's links and options, or the random
walk with probability epsilon, Eq. 7). The selector's epsilon draw for the next action is
made ahead, when the previous action was chosen (:meth:`EpsilonGreedy.draw_ahead`): when
it chose the random walk (every step while epsilon is 1, the first episode), Eq. 4-5 are
not solved for that step, as work that cannot change the next action need not be done;
the graph's estimator knows the same from the selector's last ``Action``
(``walk_next``). A greedy probe
(``act(explore=False)``) climbs the potentials of Eq. 5 without options: the learnt
policy. The agent sees only its sensation (a vector of the dimension its
:class:`~tmgwr_agent.core.senses.Senses` declare), its touch sensor (``bumped``) and the
goal's sensation, and acts with the world's motor primitives: no reward, no cell index, no
geometry, no transition model (Table 1).

The ROS nodes run exactly these four pieces in separate processes, in the same order, so
a seed gives the same trajectory in-process and over the graph.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Mapping

import numpy as np

from tmgwr_agent.core.action_selector import ActionSelector, SelectorConfig
from tmgwr_agent.core.motivation import MotivationConfig, MotivationEstimator
from tmgwr_agent.core.outcome import EPISODE_START, Outcome
from tmgwr_agent.core.preprocessor import PreprocessorConfig, SensoryPreprocessor
from tmgwr_agent.core.senses import Senses
from tmgwr_agent.core.sensorimotor_map import MapConfig, SensorimotorMap, survivor
from tmgwr_common.params import make_config, resolve, specs


@dataclass(frozen=True)
class TMGWRConfig:
    """The agent's hyperparameters: one config per module of Fig. 1a. Their names form one
    flat namespace (no two modules share a name), as the ROS parameters of the nodes do."""

    preprocessor: PreprocessorConfig = PreprocessorConfig()
    map: MapConfig = MapConfig()
    motivation: MotivationConfig = MotivationConfig()
    selector: SelectorConfig = SelectorConfig()

    def as_dict(self) -> dict[str, Any]:
        """The flat parameter dict."""
        return {k: v for f in fields(self) for k, v in getattr(self, f.name).as_dict().items()}


#: The config class of each part (the field's default is an instance of it).
_PARTS = {f.name: type(f.default) for f in fields(TMGWRConfig)}

#: Every parameter of the agent (the union of the nodes' core parameters).
SPECS = specs(*_PARTS.values())


def tmgwr_config(overrides: Mapping[str, Any] | None = None, where: str = "") -> TMGWRConfig:
    """The defaults of the specs updated by a flat dict of overrides, every value checked and
    an unknown name refused naming the nearest known one."""
    flat = resolve(SPECS, overrides, where)
    return TMGWRConfig(**{part: make_config(cls, {p.name: flat[p.name] for p in specs(cls)},
                                            where)
                          for part, cls in _PARTS.items()})


class TMGWRAgent:
    name = "tmgwr"

    def __init__(self, senses: Senses, rng: np.random.Generator,
                 config: TMGWRConfig | Mapping[str, Any] | None = None):
        """``senses``: what the world gives the agent to sense and act with;
        ``config``: a TMGWRConfig, or a flat dict of parameter overrides."""
        if not isinstance(senses, Senses):
            raise TypeError(f"TMGWRAgent takes the world's Senses (the sensation's dimension "
                            f"and motor primitives), got {type(senses).__name__}")
        if not isinstance(config, TMGWRConfig):
            config = tmgwr_config(config)
        self.config = config
        self.senses = senses
        self.preprocessor = SensoryPreprocessor(config.preprocessor, senses.resolution)
        self.map = SensorimotorMap(dim=senses.dim, action_dim=senses.action_dim,
                                   config=config.map, primitives=senses.primitives)
        self.motivation = MotivationEstimator(
            config.motivation, primitives=senses.primitives,
            goal_tolerance=self.preprocessor.gain * senses.goal_tolerance,
            bounds=(self.preprocessor.gain * senses.low, self.preprocessor.gain * senses.high)
            if senses.bounded else None)
        self.selector = ActionSelector(rng, config.selector, primitives=senses.primitives)
        self.winner = -1
        self.last_action = -1
        self.last_explored = False
        self.stepped = False        # a learning step was made (its action drawn ahead)
        self.walk_next = False      # the last step's estimator: the next action walks

    # -------------------------------------------------------------- Agent protocol
    @property
    def epsilon(self) -> float:
        return self.selector.policy.epsilon

    def set_goal(self, goal_cell: Any, goal_obs: np.ndarray) -> None:
        """The goal as the agent senses it, ``goal_obs`` (``goal_cell`` is for the tabular
        agents: the TMGWR agent ignores it)."""
        self.motivation.set_goal(self.preprocessor.goal_features(goal_obs))
        self.motivation.update(self.map, skip=self.walk_next)

    def begin_episode(self, obs: np.ndarray, cell: Any = None,
                      learn: bool = True) -> None:
        self.step(obs, EPISODE_START, learn)

    def observe(self, obs: np.ndarray, info: Any, learn: bool = True) -> None:
        self.step(obs, Outcome.of_step(info), learn)

    def act(self, explore: bool = True) -> int:
        if explore:
            if not self.motivation.solved and not self.selector.policy.draw_ahead():
                self.motivation.update(self.map)    # epsilon fell since the estimator ran
            options, V = self.motivation.option_terms, self.motivation.V
        else:
            options, V = None, self.motivation.exploit(self.map)
        a, self.last_explored = self.selector.select(self.map.links_of, self.winner, V,
                                                     self.motivation.goal_node, explore,
                                                     options)
        self.last_action = a
        return a

    def state_dict(self) -> dict:
        """What continues a run besides the map (SensorimotorMap.state_dict) and the
        generator: the estimator's outcome memory and the selector's state."""
        return {"motivation": self.motivation.state_dict(),
                "selector": self.selector.state_dict(),
                "agent": {"stepped": int(self.stepped), "walk_next": int(self.walk_next)}}

    def load_state_dict(self, d: dict) -> None:
        self.motivation.load_state_dict(d["motivation"])
        self.selector.load_state_dict(d["selector"])
        self.stepped = bool(d.get("agent", {}).get("stepped", 0))
        self.walk_next = bool(d.get("agent", {}).get("walk_next", 0))

    # -------------------------------------------------------------- one pass of Fig. 1a
    def step(self, obs: np.ndarray, outcome: Outcome, learn: bool = True) -> None:
        """Everything the agent does with one observation, in the order of the node ring
        (each line is what one node of the graph calls): the sensation is preprocessed,
        the map learns it (Eq. 1-2 on the link just traversed), the potentials are
        re-solved (the estimator first notes what the action did, Eq. 5'; not when the
        next action's epsilon draw, made ahead, chose the random walk: the selector's
        ``Action`` carries it over the graph, so the first step, with no action before it,
        is solved) and the selector records what its last action did. A greedy probe (``learn``
        False) only finds the winner and moves the walk on."""
        x = self.preprocessor(obs, episode_start=outcome.episode_start)  # sensory_preprocessor
        acted_from = selected_from = self.winner     # (the graph's selector sees no merges)
        self.winner = self.map.experience(x, outcome, learn)             # map_learner
        if self.map.merges:         # nodes merged this step (one node a place)
            self.motivation.merge(self.map.merges)
            acted_from = survivor(acted_from, self.map.merges)
        if self.map.bump_from is not None:      # a bump taken at another place than the
            acted_from = self.map.bump_from     # node's moves (sensorimotor_map.py)
        if learn:
            self.motivation.record(acted_from, self.winner, self.map.inserted,  # motivation_
                                   outcome, self.map.w)                           # estimator
            self.walk_next = self.stepped and self.selector.policy.draw_ahead()
            self.motivation.update(self.map, skip=self.walk_next)
            self.stepped = True
        self.selector.record(selected_from, outcome, learn)              # action_selector
