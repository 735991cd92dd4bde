"""What maze_sim and tmgwr_agent share: parameter declarations, topic names, QoS, the node
main loop and the data-file finder. ROS-free except :mod:`.node` and :mod:`.qos`."""
