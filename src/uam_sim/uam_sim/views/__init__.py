"""Views of a run: the Rerun log (``rerun_log``), the standard-message view topics
(``std_msgs_export``), the live Foxglove server (``foxglove_live``), the movie (``movie``) and a
replay's timing (``replay``)."""
