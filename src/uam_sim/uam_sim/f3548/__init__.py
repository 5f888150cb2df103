"""The ASTM F3548 interface: the USS-USS server (``uss_server``: an intent store and a Flask app) and
a recording's intents as JSON (``export_f3548``)."""
