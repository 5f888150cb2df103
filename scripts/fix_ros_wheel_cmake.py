"""Rewrite the wheel builder's paths in the ROS 2 Jazzy wheels' exported CMake files.

The ``ros-jazzy-*`` wheels on PyPI export CMake targets (``share/*/cmake/*.cmake``) whose include
directories name the machine the wheels were built on: ``/opt/python/cp3XX-cp3XX/include/python3.XX``
and ``.../site-packages/numpy/_core/include``. CMake refuses imported targets with non-existent
include paths, so every package that generates interfaces depending on e.g. geometry_msgs fails.
This rewrites both prefixes to this interpreter's include directory and numpy's. Idempotent: a
second run finds nothing to change.

Usage: python fix_ros_wheel_cmake.py <venv prefix>
"""

from __future__ import annotations

import pathlib
import re
import sys
import sysconfig


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    prefix = pathlib.Path(argv[1])
    import numpy

    py_include = sysconfig.get_paths()["include"]
    np_include = numpy.get_include()
    if not pathlib.Path(py_include, "Python.h").exists():
        print(
            f"Python headers not found at {py_include} (no Python.h): install them, e.g. "
            f"apt-get install python3-dev",
            file=sys.stderr,
        )
        return 1
    numpy_re = re.compile(r"/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/_core/include")
    include_re = re.compile(r"/opt/python/cp3\d+-cp3\d+/include/python3\.\d+")
    changed = 0
    for path in sorted(prefix.glob("share/*/cmake/*.cmake")):
        text = path.read_text()
        if "/opt/python/" not in text:
            continue
        new = include_re.sub(py_include, numpy_re.sub(np_include, text))
        if new != text:
            path.write_text(new)
            changed += 1
    left = [p for p in prefix.glob("share/*/cmake/*.cmake") if "/opt/python/" in p.read_text()]
    if left:
        print(f"unexpected wheel-builder paths remain in: {', '.join(map(str, left))}", file=sys.stderr)
        return 1
    print(f"[setup]   rewrote {changed} CMake file(s)" if changed else "[setup]   nothing to rewrite")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
