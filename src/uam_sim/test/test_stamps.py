"""Stamp conversion has one home (uam_contract.stamps): it was written out five times (analysis/audit
``_t``, ``rerun_log._stamp_s``, ``movie._t``, ``conversions.from_time``) and the nanosecond form
four times, free to drift apart."""

from __future__ import annotations

import re
from pathlib import Path
from types import SimpleNamespace as NS

from uam_contract.stamps import sim_stamp_ns, stamp_ns, stamp_s

ROOT = Path(__file__).resolve().parents[3]


def test_stamps_in_seconds_and_nanoseconds():
    assert stamp_s(NS(sec=3500, nanosec=0)) == 3500.0
    assert stamp_s(NS(sec=12, nanosec=250_000_000)) == 12.25
    assert stamp_ns(NS(sec=1736121600, nanosec=999_999_999)) == 1736121600_999_999_999  # exact, no float
    assert sim_stamp_ns(NS(clock=NS(sec=2, nanosec=5))) == 2_000_000_005
    assert sim_stamp_ns(NS(data=1)) is None


def test_every_package_converts_stamps_with_the_one_helper():
    # int(x.sec) + int(x.nanosec) * 1e-9, or int(x.sec) * N + int(x.nanosec), written anywhere else
    pattern = re.compile(r"int\([\w.]*\.sec\)\s*(\+|\*\s*[\w.]+\s*\+)\s*int\([\w.]*\.nanosec\)")
    copies = []
    for path in sorted((ROOT / "src").glob("*/*/**/*.py")):
        if "/test/" in str(path) or path.name == "stamps.py":
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if pattern.search(line):
                copies.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert copies == [], "stamp conversions outside uam_contract.stamps:\n" + "\n".join(copies)

    from uam_planner.nodes import conversions
    assert conversions.from_time is stamp_s and conversions.stamp_ns is stamp_ns
