"""uam_sim: demand, fleet, recording, analysis and the paper's study (no rclpy at import time).

One job per module (imports only point down this list's layers; ``test/test_layering.py``):

- demand and flight: ``demand`` (request generator, demand files), ``fleet`` (kinematics),
  ``cdr`` (CDR bytes: the simulator's encoders, exact size, stamps/ids/positions read from bytes);
- recordings: ``mcap_schema`` (type names, definitions, hashes), ``qos_yaml`` (offered QoS),
  ``stamps`` (a message's simulation time), ``mcap_writer`` (:class:`McapRecorder`),
  ``mcap_reader`` (read, decode, metadata), ``mcap_recover``, ``recording_bench``,
  ``recording`` (the ``python -m uam_sim.recording`` command; re-exports the names above),
  ``replay`` (timing of a replay), ``rerun_log``;
- analysis: ``audit`` (exact separation audits: pairwise on plans, time sweep on trajectories),
  ``flown_audit`` (plan versions chained into what flew; incursions into recorded constraints),
  ``analysis`` (summary of a recording and its integrity checks; ``python -m uam_sim.analysis``),
  ``recorded_instances`` (the MWIS instances of a recording; the ``.mcap`` corpus reader that
  ``uam_solvers.instances`` finds through an entry point);
- the study: ``experiment_config`` (parameters), ``network_spec`` (the network), ``scenario``
  (one cell in process), ``sweep`` (cells, keys, resumption, processes), ``files`` (atomic JSON,
  CSV), ``tables`` (CSV tables, corpus, timing table), ``tts_study``, ``recorded_study``
  (``--from-mcap``), ``machine``, ``figures``, ``report``, and ``experiment`` (the command line and
  :func:`~uam_sim.experiment.run_experiment`; re-exports the study's entry points);
- the capacity study (airspace modes x arms on top of the study's cells): ``capacity_study``
  (arms, one pool, tables, instance-size study; ``python -m uam_sim.capacity_study``) and
  ``capacity_report`` (report and figures from its tables).

- ASTM F3548 (issue 25, docs/f3548.md): ``uss_server`` (the USS-USS interface over HTTP: an
  intent store and a Flask app) and ``export_f3548`` (a recording's intents as JSON;
  ``python -m uam_sim.export_f3548``).

``nodes/`` holds the ROS glue (generator, simulator, recorder, replay, uss).
"""
