"""Audits and verdicts: exact separation of plans and trajectories (``separation``), plan versions
chained into what flew and incursions into constraints (``flown_audit``), the audit of the flown
tracks (``flown``), and the summary of a recording with its integrity checks and verdict
(``analysis``)."""
