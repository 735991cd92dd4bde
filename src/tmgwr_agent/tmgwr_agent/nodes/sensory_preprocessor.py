"""``ros2 run tmgwr_agent sensory_preprocessor``: raw Observation -> Features (section 3.2).

Wraps :class:`~tmgwr_agent.core.preprocessor.SensoryPreprocessor`: ``x = preprocessor(sensors,
episode_start)`` and the goal sensation in feature space; passes the lockstep context
(executed action, bump, terminal flags) on to the map learner. What the world declares of its
sensor (``SensorInfo`` on ``/world_senses``, latched: the goal region and the sensor's range,
in sensation units) goes on in feature units, scaled by the same gain, on
``/feature_senses`` (latched): the motivation estimator's, as the in-process agent scales
them (:class:`~tmgwr_agent.core.agent.TMGWRAgent`).
"""

from __future__ import annotations

import math

from rclpy.node import Node

from tmgwr_agent.core.preprocessor import PreprocessorConfig, SensoryPreprocessor
from tmgwr_agent.world_senses import node_senses
from tmgwr_common import topics
from tmgwr_common.cdr import codec
from tmgwr_common.lockstep import Lockstep
from tmgwr_common.node import (
    LATCHED_QOS,
    NODE_OPTIONS,
    STEP_QOS,
    declare_parameters,
    np_f64,
    run,
    subscribe_decoded,
)
from tmgwr_common.params import WORLD_PARAM
from tmgwr_interfaces.msg import Features, Observation, SensorInfo

FEATURES = codec(Features)
#: Runs whose sensor declarations are kept (see ``on_world_senses``).
SENSES_RUNS = 8


class SensoryPreprocessorNode(Node):
    def __init__(self):
        super().__init__("sensory_preprocessor", **NODE_OPTIONS)
        config, p = declare_parameters(self, PreprocessorConfig, (WORLD_PARAM,))
        self.core = SensoryPreprocessor(config, node_senses(p["world"]).resolution)
        pub = self.create_publisher(Features, topics.FEATURES, STEP_QOS)
        self.lockstep = Lockstep(pub, logger=self.get_logger(), what="observation")
        subscribe_decoded(self, Observation, topics.OBSERVATION, self.on_observation, STEP_QOS)
        self.senses_pub = self.create_publisher(SensorInfo, topics.FEATURE_SENSES, LATCHED_QOS)
        # the declarations per run id (the newest SENSES_RUNS and the run being stepped), and
        # the run whose declaration is latched: the run of the newest observation
        self.senses: dict[int, SensorInfo] = {}
        self.senses_run: int | None = None
        self.create_subscription(SensorInfo, topics.WORLD_SENSES, self.on_world_senses,
                                 LATCHED_QOS)
        self.get_logger().info(f"sensory_preprocessor ready: {config.as_dict()}")

    def on_observation(self, m):
        if m.run_id != self.senses_run and m.run_id in self.senses:
            self.publish_senses(m.run_id)       # the latched declaration follows the run
        self.lockstep.on_step(m.run_id, m.step_id, lambda: self.features(m))

    def features(self, m) -> bytes:
        """The Features of Observation ``m`` (fields read by tmgwr_common.cdr), serialized."""
        x = self.core(np_f64(m.sensors), episode_start=m.episode_start)
        return FEATURES.encode(FEATURES.new(
            header=m.header, run_id=m.run_id, step_id=m.step_id, episode=m.episode,
            features=x, goal_features=self.core.goal_features(np_f64(m.goal_sensors)),
            gain=float(self.core.gain), episode_start=m.episode_start, action=m.action,
            motor=m.motor, bumped=m.bumped, goal_reached=m.goal_reached,
            terminal=m.terminal, truncated=m.truncated))

    def on_world_senses(self, m: SensorInfo):
        """The world's sensor declaration in feature units (this node's gain per sensation
        unit: the message's own ``gain`` is 1, its units the sensation's)."""
        if not (m.gain > 0.0 and math.isfinite(m.gain)) or len(m.low) != len(m.high):
            self.get_logger().error(f"{topics.WORLD_SENSES}: refused a declaration with gain "
                                    f"{m.gain}, {len(m.low)} low and {len(m.high)} high "
                                    "values (a gain > 0 and as many of each)")
            return
        g = float(self.core.gain) / m.gain
        out = SensorInfo(header=m.header, run_id=m.run_id, gain=m.gain * g,
                         goal_tolerance=g * m.goal_tolerance)
        out.low = (g * np_f64(m.low)).tolist()
        out.high = (g * np_f64(m.high)).tolist()
        self.senses.pop(m.run_id, None)
        self.senses[m.run_id] = out
        for old in [r for r in self.senses if r != self.senses_run][
                :max(0, len(self.senses) - SENSES_RUNS)]:
            del self.senses[old]                # the oldest, never the run being stepped
        if self.senses_run in (None, m.run_id):
            self.publish_senses(m.run_id)

    def publish_senses(self, run: int):
        """Latch run ``run``'s declaration on /feature_senses (its depth is one: a node that
        joins later reads the declaration of the run being stepped, not a stray's)."""
        self.senses_run = run
        self.senses_pub.publish(self.senses[run])

    def on_shutdown(self):
        print(f"sensory_preprocessor: {self.lockstep.timer.summary()}", flush=True)


def main(args=None):
    raise SystemExit(run(SensoryPreprocessorNode, "sensory_preprocessor", args))


if __name__ == "__main__":
    main()
