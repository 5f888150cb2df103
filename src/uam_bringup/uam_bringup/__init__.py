"""The rclpy glue every node shares, above the contract and free of the libraries.

- :mod:`uam_bringup.qos`: the contract's QoS (:mod:`uam_contract.names`) as rclpy profiles;
- :mod:`uam_bringup.params`: a node's parameter table (:mod:`uam_contract.params`) declared on
  the node, with validation of run-time changes;
- :mod:`uam_bringup.runtime`: a node's ``main()`` (signals, executor, clean-up, CPU report);
- :mod:`uam_bringup.journal`: the planner's journal of its own approvals;
- the launch file (``launch/uam.launch.py``).

Layering (docs/architecture.md, test/test_layering.py): uam_contract < uam_solvers < uam_planner
< uam_sim are the libraries; this package imports only the contract (and rclpy); the ``nodes``
subpackages of the libraries import it and their own library.
"""
