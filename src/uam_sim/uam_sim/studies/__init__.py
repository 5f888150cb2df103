"""Studies built on the runner: the paper's study (``experiment``, ``tts_study``, ``recorded_study``),
the capacity study, the decision study, the Monte-Carlo of disturbances (``montecarlo``), and the
recording benchmark (``recording_bench``)."""
