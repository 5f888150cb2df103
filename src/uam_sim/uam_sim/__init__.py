"""uam_sim: the world a run flies in, its recording, its audit, its views and the studies built on
it (no rclpy at import time).

Rooms, lowest first; a module imports only from its own room or a lower one
(``test/test_layering.py`` holds the order):

- ``world``: demand (``demand``), kinematics (``fleet``), disturbances (``disturbance``), the
  conformance of what flew (``conformance``) and what a run's flights measure (``flights``);
- ``recording``: MCAP as rosbag2 writes it (``mcap_schema``, ``cdr``, ``mcap_writer``,
  ``mcap_reader``, ``mcap_recover``; the package re-exports them) and the MWIS instances of a
  recording (``recorded_instances``);
- ``audit``: exact separation (``separation``), plan versions and incursions (``flown_audit``),
  the flown tracks (``flown``) and the summary and verdict of a recording (``analysis``);
- ``views`` (Rerun, standard messages, Foxglove, movie, replay timing) and ``f3548`` (the USS
  server and the export of a recording's intents), side by side;
- ``runner``: the in-process runner (``scenario``), its configuration (``experiment_config``,
  ``network_spec``) and the sweep of cells (``sweep``, ``tables``, ``files``, ``dask_cluster``);
- ``reports``: statistics, figures and the studies' reports from their tables;
- ``studies``: the paper's study (``experiment``), the capacity and decision studies, the
  Monte-Carlo of disturbances and the recording benchmark.

The top-level modules are the commands (``python -m uam_sim.analysis``, ``.experiment``,
``.montecarlo``, ...): each only runs a room's ``main``. ``nodes/`` holds the ROS glue.
"""
