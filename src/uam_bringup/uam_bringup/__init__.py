"""The ROS contract of the UAM node graph, one home for what every node must agree on.

- :mod:`uam_bringup.contract`: topic and service names (relative), QoS (as plain data), frame id;
- :mod:`uam_bringup.qos`: the same QoS as rclpy profiles (imports rclpy);
- :mod:`uam_bringup.conversions`: messages <-> library types, rclpy-free and duck-typed (works on
  generated messages and on messages decoded by ``rosbags`` or ``mcap_ros2``);
- :mod:`uam_bringup.params`: every node's parameter table (declaration, run-time changes, docs);
- :mod:`uam_bringup.runtime`: a node's ``main()`` (signals, executor, clean-up, CPU report).

Layering: the libraries (uam_solvers < uam_planner < uam_sim) never import this package; the
``nodes`` subpackages import it (test/test_layering.py checks it).
"""
