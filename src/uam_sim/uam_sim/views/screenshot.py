"""A Rerun recording (.rrd) rendered to a PNG by the real Rerun viewer, headless.

The viewer is the ``rerun`` binary of the rerun-sdk wheel, run under Xvfb and rendering with
Mesa's software Vulkan (lavapipe); scripts/setup.sh installs both when missing. The viewer's
``--screenshot-to`` saves one frame and quits. The blueprint puts the time cursor on the newest
data, so the frame shows the end of the recording.

    python -m uam_sim.views.screenshot RUN.rrd OUT.png [--size 1400x800]
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Iterator

#: the window the README's picture and the screenshot tests use [px]
WINDOW = (1400, 800)


def rerun_cli() -> str:
    """Path of the ``rerun`` binary beside this Python, else on PATH; RuntimeError if neither."""
    exe = Path(sys.executable).with_name("rerun")
    found = str(exe) if exe.exists() else shutil.which("rerun")
    if not found:
        raise RuntimeError("rerun: the CLI of rerun-sdk is not installed (scripts/setup.sh installs it)")
    return found


@contextlib.contextmanager
def xvfb_display() -> Iterator[str]:
    """A private X display (``":N"``) for the time of the ``with`` block.

    Xvfb picks a free number and reports it through a pipe. The screen is more than twice the
    window in physical pixels (the viewer draws at 2x: 2800x1600 for 1400x800), so that the
    pointer, which starts at the centre of the screen, is outside the window and no hover
    tooltip covers the view (at 4000x3000 one covered a plot)."""
    xvfb = shutil.which("Xvfb")
    if not xvfb:
        raise RuntimeError("Xvfb: not installed (scripts/setup.sh installs the Debian package xvfb)")
    r, w = os.pipe()
    proc = subprocess.Popen([xvfb, "-displayfd", str(w), "-screen", "0", "6400x4000x24", "-nolisten", "tcp"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(w)
    try:
        with os.fdopen(r) as f:
            number = f.readline().strip()
        if not number:
            raise RuntimeError("Xvfb: reported no display number")
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def screenshot(rrd: str | os.PathLike, out: str | os.PathLike, display: str,
               window: tuple[int, int] = WINDOW, timeout_s: float = 240.0) -> Path:
    """Open ``rrd`` in the viewer on X display ``display`` at ``window`` (width, height) [px] and
    save the frame to ``out`` (PNG, in physical pixels). Raises RuntimeError with the viewer's
    output when it writes no picture."""
    out = Path(out)
    with tempfile.TemporaryDirectory(prefix="rerun-shot-") as runtime:
        env = dict(os.environ, DISPLAY=display, XDG_RUNTIME_DIR=runtime)
        env.pop("WAYLAND_DISPLAY", None)   # force X11 (Xvfb)
        # the viewer's notices of the software rasteriser and the container would cover the
        # top right of the picture; errors still show
        env["RUST_LOG"] = "error"
        cmd = [rerun_cli(), str(rrd), "--port", str(_free_port()), "--screenshot-to", str(out),
               "--window-size", f"{window[0]}x{window[1]}"]
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
    if done.returncode != 0 or not out.exists():
        raise RuntimeError(f"rerun --screenshot-to {out}: exit code {done.returncode}, no picture; "
                           f"{done.stdout[-3000:]}{done.stderr[-3000:]}")
    return out


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m uam_sim.views.screenshot",
                                 description="render a Rerun .rrd to a PNG with the real viewer, headless")
    ap.add_argument("rrd")
    ap.add_argument("out", help="the PNG to write")
    ap.add_argument("--size", default=f"{WINDOW[0]}x{WINDOW[1]}", help="window WIDTHxHEIGHT [px]")
    args = ap.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        ap.error(f"--size: {args.size!r} is not WIDTHxHEIGHT, e.g. 1400x800")
    if not Path(args.rrd).is_file():
        ap.error(f"rrd: {args.rrd!r} is not a file")
    try:
        with xvfb_display() as display:
            screenshot(args.rrd, args.out, display, (width, height))
    except (RuntimeError, subprocess.TimeoutExpired) as exc:
        print(f"screenshot: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {args.out} ({width}x{height}) from {args.rrd}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
