"""The contract of the UAM node graph, below every library (docs/architecture.md):

- :mod:`uam_contract.names`: topic and service names, the frame, the QoS of each topic;
- :mod:`uam_contract.qos_spec`: QoS profiles as plain records (and rosbag2's YAML of them);
- :mod:`uam_contract.ids` and :mod:`uam_contract.wire`: what an id and a request may be;
- :mod:`uam_contract.stamps`: builtin_interfaces/Time in seconds and nanoseconds;
- :mod:`uam_contract.params`: every node's parameter table (defaults, ranges, docs).

Plain Python: no rclpy and no library of the project, so every library and tool can read it.
"""
