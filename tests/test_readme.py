"""The README's two commands: CI runs the test command; the main job's run works as written."""

from __future__ import annotations

import csv
import json
import re
import shlex
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from agvsim.net import free_port

ROOT = Path(__file__).resolve().parents[1]


def _commands() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Two commands", 1)[1].split("\n## ", 1)[0]
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", section, re.S)]


def test_readme_has_exactly_two_commands_and_ci_runs_the_test_one():
    cmds = _commands()
    assert len(cmds) == 2 and all("\n" not in c for c in cmds)
    main, tests = cmds
    assert "agvsim serve" in main and "pytest" in tests
    assert tests in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


@pytest.mark.slow
def test_readme_main_command_serves_the_app_on_localhost():
    main = _commands()[0]
    serve = shlex.split(main.split("&&")[-1])
    assert serve[0].endswith("agvsim") and serve[1] == "serve"
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "agvsim.cli", *serve[1:], "--port", str(port)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        lines: list[str] = []
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "agvsim app on" in line:
                break
        banner = "".join(lines)
        found = re.search(rf"agvsim app on (http://127\.0\.0\.1:{port}/\?token=[\w-]+)", banner)
        assert found, banner
        page = urllib.request.urlopen(found[1], timeout=30).read()
        assert b"<html" in page.lower() or b"<!doctype html" in page.lower()
        with pytest.raises(urllib.error.HTTPError) as refused:  # without the token: no app
            urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30)
        assert refused.value.code == 403
        listening = [c for c in _listeners(port)]
        assert listening and all(addr == "127.0.0.1" for addr in listening), listening
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    assert proc.returncode == 0


def _listeners(port: int) -> list[str]:
    """Local addresses listening on ``port`` (from /proc/net/tcp and tcp6)."""
    out = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            local, state = row.split()[1], row.split()[3]
            addr, p = local.split(":")
            if state == "0A" and int(p, 16) == port:  # LISTEN
                if len(addr) == 8:
                    out.append(socket.inet_ntoa(bytes.fromhex(addr)[::-1]))
                else:
                    out.append("ipv6:" + addr)
    return out


@pytest.mark.slow
def test_readme_headless_run_writes_its_outputs(tmp_path):
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Headless runs", 1)[1].split("\n## ", 1)[0]
    cmd = re.findall(r"```bash\n(.*?)```", section, re.S)[0].strip()
    run = shlex.split(cmd)
    assert run[0].endswith("agvsim") and run[1] == "run"
    args = run[2:]
    out = tmp_path / "out"
    args[args.index("--out") + 1] = str(out)
    res = subprocess.run(
        [sys.executable, "-m", "agvsim.cli", "run", *args, "--duration", "4", "--quiet"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run"]["simulated_time_s"] == 4.0
    assert summary["run"]["status"] == "completed"
    assert len(summary["robots"]) == 4
    with (out / "trajectory.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert rows[0].keys() >= {"t", "robot", "x", "y", "theta", "vx", "vy", "omega", "wheel1_rad_s"}
    assert len(rows) == 4 * (200 + 1)  # 4 robots x (t = 0 and 200 steps of 0.02 s)
    png = (out / "plot.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 20_000


def test_help_lists_every_command():
    res = subprocess.run(
        [sys.executable, "-m", "agvsim.cli", "--help"], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0
    for cmd in ("run", "serve", "slam", "validate", "bench", "models", "statechart"):
        assert cmd in res.stdout


def test_statechart_command_prints_mermaid_and_dot():
    def run(*args):
        return subprocess.run(
            [sys.executable, "-m", "agvsim.cli", "statechart", *args],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=ROOT,
        )

    mermaid = run("avoid")
    assert mermaid.returncode == 0, mermaid.stderr
    assert mermaid.stdout.startswith("stateDiagram-v2") and "drive --> turn_right" in mermaid.stdout
    dot = run("examples/square_path.py", "--format", "dot")
    assert dot.returncode == 0 and dot.stdout.startswith("digraph")
    bad = run("no_such_file.py")
    assert bad.returncode == 2 and "no_such_file.py" in bad.stderr
    assert "Traceback" not in bad.stderr
