"""The machine and commit a study ran on, for its report."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

from .experiment_config import REPO_ROOT


def machine_info() -> dict:
    """commit (flagged when src/ or config/ have uncommitted changes), python, platform, cpu, cores."""
    try:
        commit = subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"],
                                capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(REPO_ROOT), "status", "--porcelain", "--",
                                "src", "config"], capture_output=True, text=True,
                               timeout=10).stdout.strip() != ""
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "unknown", False
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"commit": commit + (" (with uncommitted changes)" if dirty else ""),
            "python": sys.version.split()[0], "platform": platform.platform(), "cpu": cpu,
            "cores": os.cpu_count()}
