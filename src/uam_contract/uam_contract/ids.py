"""What an id may be, wherever it comes from (the wire, a demand file): one rule, free of ROS.

Operator and request ids are 1 to MAX_ID_LENGTH characters of letters, digits, ``_``, ``-`` and
``.``; node ids (origins, destinations) at most MAX_NODE_ID_LENGTH characters. A bad value is
shown cut to MAX_ECHO_CHARS characters with its full length, so a 100,000-character id never
makes a 100 kB error or log line.
"""

from __future__ import annotations

import re
from typing import Any

MAX_ID_LENGTH = 64
ID_PATTERN = re.compile(r"[A-Za-z0-9_.\-]{1,%d}" % MAX_ID_LENGTH)
MAX_NODE_ID_LENGTH = 128
MAX_ECHO_CHARS = 40


def echo(value: Any) -> str:
    """``repr`` of a value cut to MAX_ECHO_CHARS characters, with the full length said."""
    text = repr(value)
    if len(text) <= MAX_ECHO_CHARS:
        return text
    size = len(value) if isinstance(value, (str, bytes, list, tuple)) else len(text)
    return f"{text[:MAX_ECHO_CHARS]}... ({size} characters)"


def check_id(field: str, value: Any) -> str:
    """'' if ``value`` is a valid id, else the reason naming ``field``."""
    if not isinstance(value, str) or not ID_PATTERN.fullmatch(value):
        return (f"{field}: {echo(value)} must be 1 to {MAX_ID_LENGTH} characters of letters, digits, "
                "'_', '-' and '.'")
    return ""
