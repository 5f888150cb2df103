"""Reports from the studies' tables: paired statistics (``stats``), figures (``figures``), the paper
study's report (``report``), the capacity and decision studies' reports (``capacity_report``,
``decision_report``, ``decision_metrics``)."""
