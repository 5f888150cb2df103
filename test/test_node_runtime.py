"""The node runtime (uam_bringup.runtime): a node that ends delivers what it published first.

A reliable writer that goes away takes its unacknowledged samples with it. The recorder runs at
a low priority (nice) and catches up after the run; when the simulator exited at once, the recorder sometimes
missed its last messages (the end-of-run announcement among them) and then waited for it until
run_fleet.sh stopped it 60 s later. Here the subscriber process is stopped (SIGSTOP) while the
publisher publishes and ends, as a starved recorder would be, and resumed later.
"""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest
from load_factor import slack

pytest.importorskip("rclpy", reason="needs the built workspace (source scripts/env.sh)")

N = 300

SUBSCRIBER = """
import os, sys, time, rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from std_msgs.msg import UInt32
rclpy.init()
node = rclpy.create_node("slow_subscriber")
got = []
node.create_subscription(UInt32, "flush_probe", lambda m: got.append(m.data),
                         QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10000, reliability=ReliabilityPolicy.RELIABLE))
open(sys.argv[1] + ".ready", "w").close()
end = time.monotonic() + float(sys.argv[2])
while time.monotonic() < end and len(got) < {n}:
    rclpy.spin_once(node, timeout_sec=0.05)
    if node.count_publishers("flush_probe") and not os.path.exists(sys.argv[1] + ".heard"):
        open(sys.argv[1] + ".heard", "w").close()
open(sys.argv[1], "w").write(str(len(got)))
""".replace("{n}", str(N))

PUBLISHER = """
import os, sys, time
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, HistoryPolicy
from std_msgs.msg import UInt32
from uam_bringup.runtime import run_node
go = sys.argv[1]
class Pub(Node):
    def __init__(self):
        super().__init__("flush_publisher")
        # a shallow writer history, as the clock's was: what is not acknowledged is overwritten or lost
        self.pub = self.create_publisher(UInt32, "flush_probe",
                                         QoSProfile(history=HistoryPolicy.KEEP_LAST, depth={n}, reliability=ReliabilityPolicy.RELIABLE))
        self.finished = False
        self.timer = self.create_timer(0.02, self.tick)
    def tick(self):
        if self.pub.get_subscription_count() and not os.path.exists(go + ".matched"):
            open(go + ".matched", "w").close()
        if os.path.exists(go):
            for i in range({n}):
                self.pub.publish(UInt32(data=i))
            self.finished = True
            self.timer.cancel()
            open(go + ".published", "w").close()
sys.exit(run_node(Pub, "flush_publisher", None))
""".replace("{n}", str(N))


def _wait_file(path: pathlib.Path, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if path.exists():
            return True
        time.sleep(0.05)
    return False


def test_a_node_that_ends_waits_until_a_stopped_subscriber_has_acknowledged_its_messages(tmp_path, ros_process_domain_id):
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_process_domain_id))
    count, go = tmp_path / "count", tmp_path / "go"
    sub = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, str(count), "20"], env=env)
    pub = None
    try:
        assert _wait_file(pathlib.Path(str(count) + ".ready"), 30)
        pub = subprocess.Popen([sys.executable, "-c", PUBLISHER, str(go)], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        assert _wait_file(pathlib.Path(str(go) + ".matched"), 30), "the publisher never matched the subscriber"
        # both ends have discovered each other (conditions, not sleeps)
        assert _wait_file(pathlib.Path(str(count) + ".heard"), 30), "the subscriber never saw the publisher"
        os.kill(sub.pid, signal.SIGSTOP)  # the subscriber gets no CPU, as a starved recorder
        go.touch()
        assert _wait_file(pathlib.Path(str(go) + ".published"), 60), "the publisher never ended its loop"
        # its loop has ended, but nothing is acknowledged yet: the node is still waiting
        assert pub.poll() is None, "the publisher exited before its stopped subscriber acknowledged"
        os.kill(sub.pid, signal.SIGCONT)
        out, _ = pub.communicate(timeout=60)
        assert pub.returncode == 0, out
        sub.wait(timeout=90)
        assert count.read_text() == str(N), f"the subscriber got {count.read_text()} of {N} messages"
    finally:
        for p in (sub, pub):
            if p is not None and p.poll() is None:
                os.kill(p.pid, signal.SIGCONT)
                p.kill()


ENDS_AT_ONCE = """
import os, signal, sys, time
from rclpy.node import Node
from uam_bringup.runtime import run_node
class Done(Node):
    def __init__(self):
        super().__init__("ends_at_once")
        self.finished = True
class SigintWhileFinalizing:
    # run_fleet.sh's SIGINT at the end of a run reaching a node that is still exiting: module
    # objects are destroyed after Python reset its signal handlers to the default action
    def __del__(self):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)
sys.modules["sigint_while_finalizing"] = SigintWhileFinalizing()
sys.exit(run_node(Done, "ends_at_once", None))
"""


def test_a_sigint_while_a_finished_node_exits_does_not_kill_it(ros_process_domain_id):
    """A normal run logged "node 'planner' exited with code 130": the SIGINT run_fleet.sh sends
    at the end reached the planner while the interpreter was finalizing."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_process_domain_id))
    proc = subprocess.run([sys.executable, "-c", ENDS_AT_ONCE], env=env, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, (proc.returncode, proc.stderr)


STUCK_HANDLER = """
import atexit, re, sys, time
from uam_bringup import runtime
def stuck_{kind}():
    if "{kind}" == "sleeping":
        time.sleep(60)            # releases the GIL: the watchdog thread ends the process
    else:
        re.match(r"(a+)+$", "a" * 60 + "b")   # holds the GIL for ever: only SIGALRM ends it
atexit.register(stuck_{kind})
print("handlers armed", flush=True)
runtime._exit_now(7)
"""


def test_a_hung_exit_handler_is_cut_off_and_named_whether_or_not_it_holds_the_gil():
    """A node's exit handlers get EXIT_HANDLERS_S (then the watchdog thread os._exit's with the
    node's code), or one second more if a handler holds the GIL (SIGALRM's default action ends the
    process); either way faulthandler prints the stuck handler's stack first, so the hang that
    run_fleet.sh's 10 s caught twice in CI (the recorder, the request generator) names itself."""
    from uam_bringup.runtime import EXIT_HANDLERS_S

    t0 = time.monotonic()
    procs = {kind: subprocess.Popen([sys.executable, "-c", STUCK_HANDLER.format(kind=kind)],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for kind in ("sleeping", "gil_holding")}
    out = {kind: p.communicate(timeout=60) for kind, p in procs.items()}
    took = time.monotonic() - t0
    for kind, (stdout, stderr) in out.items():
        assert "handlers armed" in stdout
        assert f"stuck_{kind}" in stderr, (kind, stderr[-2000:])   # the dump names the handler
    assert procs["sleeping"].returncode == 7                        # the node's own exit code
    assert procs["gil_holding"].returncode == -signal.SIGALRM      # ended in the kernel
    assert took < EXIT_HANDLERS_S + 1 + slack(20)                   # bounded (test/load_factor.py)


def _sigint_once_spinning(script: str, env: dict, timeout_s: float):
    """Run a node script, SIGINT it once it prints "spinning"; (process, stdout, stderr, seconds
    from the signal to its end)."""
    proc = subprocess.Popen([sys.executable, "-c", script], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "spinning"
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc, stdout, stderr, time.monotonic() - t0


HUNG_CLEANUP = """
import sys, threading
from rclpy.node import Node
from uam_bringup.runtime import run_node
class Hung(Node):
    def __init__(self):
        super().__init__("hung_cleanup")
        self.timer = self.create_timer(0.05, self.tick)
    def tick(self):
        print("spinning", flush=True)   # once: the node is in its spin loop
        self.timer.cancel()
    def close(self):
        print("closing", flush=True)
        def stuck_in_close():
            threading.Event().wait()   # never set: hangs until the watcher ends the process
        stuck_in_close()
sys.exit(run_node(Hung, "hung_cleanup", None, stateless={stateless}))
"""


def test_a_stateless_node_stuck_after_a_signal_names_its_stack_and_ends_itself(ros_process_domain_id):
    """Seventh stop: the solver node now and then outlived run_fleet.sh's 10 s after a SIGINT,
    with no clue where. After a signal the runtime's watcher prints every thread's stack if the
    node has not ended UAM_STOP_DUMP_S later (7 s; 1 s here), and a stateless node (the solver)
    is then ended with exit code 0 and a warning; the clean-up's phases are timed and printed."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_process_domain_id), UAM_STOP_DUMP_S="1.0")
    proc, stdout, stderr, took = _sigint_once_spinning(HUNG_CLEANUP.format(stateless=True), env, 30)
    assert "closing" in stdout
    assert proc.returncode == 0, (proc.returncode, stderr[-2000:])
    assert "stuck_in_close" in stderr, stderr[-2000:]          # the stack names where it hangs
    assert "[hung_cleanup] WARNING: not ended" in stderr and "keeps no state" in stderr
    assert 1.0 <= took < 1.0 + slack(15)                        # bounded (test/load_factor.py)


GIL_HOLDING_DESTROY = """
import ctypes, sys
from rclpy.node import Node
from uam_bringup.runtime import run_node
class Node_(Node):
    def __init__(self):
        super().__init__("gil_holding_destroy")
        self.timer = self.create_timer(0.05, self.tick)
    def tick(self):
        print("spinning", flush=True)
        self.timer.cancel()
    def close(self):
        print("closed", flush=True)
    def destroy_node(self):
        # what the solver node's destroy_node did in a loaded run: spin in C holding the GIL
        # (ctypes.PyDLL keeps the GIL across the call), which no Python-level watcher can cut
        print("destroying", flush=True)
        ctypes.PyDLL(None).sleep(60)
        return super().destroy_node()
sys.exit(run_node(Node_, "gil_holding_destroy", None, stateless={stateless}))
"""


@pytest.mark.parametrize("stateless", [True, False])
def test_after_a_signal_a_node_is_closed_and_not_destroyed_so_a_hanging_destroy_cannot_keep_it(
        ros_process_domain_id, stateless):
    """Ninth stop: in a loaded run the solver node hung in rclpy's destroy_node() holding the
    GIL (faulthandler showed the main thread there, state R), so its stop watcher could not end
    it and run_fleet.sh killed it after 10 s. After a stop signal every node is now closed and
    its process ends without destroy_node() or rclpy's shutdown; its exit code is its own."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_process_domain_id))
    proc, stdout, stderr, took = _sigint_once_spinning(GIL_HOLDING_DESTROY.format(stateless=stateless), env, 90)
    assert "closed" in stdout, (stdout, stderr[-2000:])
    assert "destroying" not in stdout
    assert proc.returncode == 0, (proc.returncode, stderr[-2000:])
    assert "[gil_holding_destroy] stopped by a signal" in stderr     # the clean-up is still timed
    assert took < slack(30), took   # a minute if destroy_node ran (test/load_factor.py)
