"""Recordings of the node graph: rosbag2-compatible MCAP bags and the tools around them.

rosbag2 cannot be installed from the registries here, so the project records itself, in
the MCAP ``ros2`` profile that rosbag2 and Foxglove read.

A bag is a directory ``runs/<UTC timestamp>/`` holding ``<name>_0.mcap``, ``<name>_1.mcap``
... (split by size or duration) and ``metadata.yaml`` (rosbag2 metadata version 9); each
``.mcap`` file is complete on its own (``ros2`` profile, ``ros2msg`` schemas, ``cdr``
messages, channel metadata ``offered_qos_profiles`` and ``topic_type_hash``, Statistics,
indexes and a ``rosbag2`` metadata record). It opens with rosbag2, rosbags, the ``mcap``
library and Foxglove.

Modules (one idea each):

* :mod:`.definitions` -- ``ros2msg`` schema text and RIHS01 type hashes of installed types;
* :mod:`.qos` -- QoS profiles in rosbag2's YAML form, subscription QoS for a recorder;
* :mod:`.writer` -- :class:`~.writer.BagWriter` (ROS-free), used by the recorder node
  ``tmgwr_agent.nodes.recorder`` (``ros2 run tmgwr_agent recorder``);
* :mod:`.recover` -- ``./tmgwr recover BAG [-o OUT]``: a killed recording made valid;
* :mod:`.replay` -- ``./tmgwr replay BAG [--rate R] [--topics ...] [--loop]``;
* :mod:`.report` -- ``./tmgwr report BAG [-o DIR] [--maze FILE]``: JSON + PNG figures;
* :mod:`.bench` -- the recorder's lossless throughput for ``./tmgwr bench``;
* :mod:`.cli` -- registers the three commands with ``./tmgwr``.
"""
