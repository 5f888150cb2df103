"""The README's commands as a new user runs them: every command of the sections "The two
commands", "Running the node graph" (with "Outputs and replay") and the experiments section
("Reproducing the paper's study") is extracted from README.md and run in a new shell's
environment (only PATH, HOME and the test's ROS domain: nothing of this test run's venv), each
checked for its exit code and one line of its output.

Commands are run as written, with cheap values where the README's would take long: a shorter
`--duration`, fewer rates, seeds and instances (the README says any parameter can be given as a
flag), or the small study and the recording this test just made. A README command
that no rule below covers fails the test, so a new command must come with its check.
"""

from __future__ import annotations

import os
import pathlib
import re
import shlex
import subprocess

import pytest

pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: the sections the issue names; the README calls its experiments section "Reproducing the paper's study"
SECTIONS = ("The two commands", "Running the node graph", "Outputs and replay",
            "Reproducing the paper's study")


def section_text(markdown: str, title: str) -> str:
    """The text under the heading ``title`` up to the next heading of the same or a higher level."""
    lines = markdown.splitlines()
    for i, line in enumerate(lines):
        m = re.match(r"(#+) (.*)", line)
        if m and m.group(2).strip() == title:
            level = len(m.group(1))
            body = []
            for nxt in lines[i + 1:]:
                h = re.match(r"(#+) ", nxt)
                if h and len(h.group(1)) <= level:
                    break
                body.append(nxt)
            return "\n".join(body)
    raise AssertionError(f"README.md has no section {title!r}")


def section_commands(text: str) -> list[str]:
    """Commands of a section: the lines of its indented code blocks (continuations joined,
    trailing comments dropped) and the first column of a command table (`make demo`)."""
    commands, pending = [], ""
    for line in text.splitlines():
        table = re.match(r"\| `([^`]+)` \|", line)
        if table and not table.group(1).startswith("ros2 "):  # the node table's `ros2 run` rows are the script's
            commands.append(table.group(1))
            continue
        if not line.startswith("    ") or line.startswith("    -"):
            continue
        code = line[4:]
        code = re.sub(r"\s+#\s.*$", "", code).rstrip()
        if code.endswith("\\"):
            pending += code[:-1].strip() + " "
            continue
        commands.append((pending + code.strip()).strip())
        pending = ""
    return [c for c in commands if c]


def readme_commands() -> list[str]:
    text = README.read_text(encoding="utf-8")
    seen, out = set(), []
    for title in SECTIONS:
        for c in section_commands(section_text(text, title)):
            if c not in seen:
                seen.add(c)
                out.append(c)
    return out


def fresh_env(tmp: pathlib.Path, domain_id: int) -> dict:
    """A new login shell's environment: none of this test run's venv, PYTHONPATH or ROS paths."""
    return {"PATH": "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
            "HOME": os.environ.get("HOME", str(tmp)), "LANG": "C.UTF-8",
            "ROS_DOMAIN_ID": str(domain_id), "UAM_RUNS_DIR": str(tmp / "runs")}


def run(cmd: str, env: dict, timeout_s: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", cmd], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, timeout=timeout_s)


def test_readme_commands_are_extracted_from_the_sections():
    cmds = readme_commands()
    assert "make demo" in cmds and "make test" in cmds
    assert any(c.startswith("scripts/run_fleet.sh --backend exact") for c in cmds)
    assert any(c.startswith("python -m uam_sim.experiment --config") for c in cmds)
    assert "source scripts/env.sh" in cmds
    # the forms that do not exist on the PyPI set-up are not shown as the command to type
    assert not any(c.startswith("ros2 ") for c in cmds), cmds


def test_every_readme_command_runs_as_written(tmp_path, ros_process_domain_id):
    env = fresh_env(tmp_path, ros_process_domain_id)
    demo_out = tmp_path / "demo"
    study = tmp_path / "study"
    mcap = demo_out / "run.mcap"
    in_env = "source scripts/env.sh && "

    def cheap(cmd: str) -> tuple[str, str] | None:
        """(the command to run, a line its output must hold) for a README command, or None."""
        q = shlex.quote
        if cmd == "make demo":
            return f'make demo DEMO_ARGS="--duration 60 --out {demo_out}"', "Safety audit     OK"
        if cmd == "make test":  # the test run itself: what it would run, not a run inside a run
            return "make -n test", "bash scripts/test.sh"
        if cmd.startswith("scripts/run_fleet.sh "):
            c = cmd.replace("[--mode realtime --rtf 20]", "--mode realtime --rtf 20")
            c = c.replace("[--rerun spawn]", "")  # a live viewer: not in a test
            c = re.sub(r"--duration \d+", "--duration 60", c)
            return c + f" --out {q(str(tmp_path / 'graph'))}", "Safety audit     OK"
        if cmd == "source scripts/env.sh":
            return cmd + " && command -v python rerun", str(ROOT / ".venv" / "bin" / "rerun")
        c = cmd.replace("runs/.../run.mcap", q(str(mcap)))
        if c.startswith("python -m uam_sim.analysis "):
            return in_env + c, "Safety audit     OK"
        if c.startswith("install/uam_sim/lib/uam_sim/replay "):
            return in_env + c.replace("rate:=10.0", "rate:=60.0"), "replay done:"
        if c.startswith("rerun ") and c.endswith(".rrd"):
            # the viewer on the demo's .rrd: here Rerun checks the file, headless
            rrd = q(str(demo_out / "run.rrd"))
            return in_env + f"rerun rrd verify {rrd} && echo verified {rrd}", "verified "
        if c.startswith("rerun ") and c.endswith(".mcap"):
            # the viewer: here Rerun reads the same file into an .rrd, headless
            return (in_env + f"rerun mcap convert {q(str(mcap))} -o {q(str(tmp_path / 'from_mcap.rrd'))}"
                    f" && ls {q(str(tmp_path / 'from_mcap.rrd'))}"), "from_mcap.rrd"
        if c.startswith("python -m uam_sim.experiment "):
            return (in_env + c + f" --out {q(str(study))} --rates 2 --methods fifo,greedy --seeds 1"
                    " --duration 120 --workers 1 --no-tts --no-progress"), "report: "
        if c.startswith("python -m uam_solvers.tts "):
            c = c.replace("--generate 629", "--generate 3")
            c = c.replace("results/instances.jsonl", q(str(study / "instances.jsonl")))
            c = c.replace("--out results/tts", f"--out {q(str(tmp_path / 'tts'))}")
            return in_env + c + " --limit 3 --repetitions 1 --num-reads 10", "wrote "
        return None

    commands = readme_commands()
    uncovered = [c for c in commands if cheap(c) is None]
    assert not uncovered, f"README commands without a check in this test: {uncovered}"
    # order: the runs first, then what reads their outputs
    order = ["make", "scripts/", "source", "python -m uam_sim.analysis", "install/", "rerun",
             "python -m uam_sim.experiment", "python -m uam_solvers.tts"]
    commands.sort(key=lambda c: next((i for i, p in enumerate(order) if c.startswith(p)), len(order)))
    failures = []
    for cmd in commands:
        argv, line = cheap(cmd)
        proc = run(argv, env)
        if proc.returncode != 0 or line not in proc.stdout:
            failures.append(f"README: {cmd}\n  ran: {argv}\n  exit {proc.returncode}, "
                            f"expected a line with {line!r}; output ends:\n{proc.stdout[-1500:]}")
    assert not failures, "\n\n".join(failures)
    # the demo's recording passes Rerun's own check of its structure and timelines
    checked = run(in_env + f"rerun mcap check {shlex.quote(str(mcap))}", env)
    assert checked.returncode == 0 and "/uam/epoch_sync" in checked.stdout, checked.stdout[-2000:]
    assert "PROBLEM" not in checked.stdout, checked.stdout[-2000:]


def test_run_fleet_help_and_backend_list_say_what_the_script_does(tmp_path, ros_process_domain_id):
    env = fresh_env(tmp_path, ros_process_domain_id)
    helped = run("scripts/run_fleet.sh --help", env)
    assert helped.returncode == 0
    # the help ended mid-sentence ("... the kernel (each is started")
    assert helped.stdout.rstrip().endswith("still closes its files."), helped.stdout[-300:]
    assert "--out DIR" in helped.stdout
    listed = run("scripts/run_fleet.sh --backend list", env)
    assert listed.returncode == 0, listed.stdout
    # `auto` was called "the default" while the script (and make demo) runs exact
    assert "runs --backend exact unless told otherwise" in listed.stdout
    assert not re.search(r"^auto .*the default", listed.stdout, re.M), listed.stdout
