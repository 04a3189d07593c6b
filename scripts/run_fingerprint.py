"""Fingerprint what agvsim computes, to check that a refactor changes no behaviour.

Runs every single-run scenario in ``scenarios/`` headless (``agvsim run``), a small sweep, the
grading example, seeded gym roll-outs, an app session with edits, and the in-process fleet with
its master; hashes every output that does not depend on the wall clock (trajectory.csv,
summary.json without its timing fields, each run.mcap message, result tables, gym
observations). Two commits give the same fingerprints exactly when they compute the same
numbers on this machine.

    python scripts/run_fingerprint.py --out fp_before.json
    ... change the code ...
    python scripts/run_fingerprint.py --compare fp_before.json

Floating-point results can differ between CPUs, so compare fingerprints taken on one machine.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TIMING_KEYS = {
    "wall_time_s",
    "real_time_factor",
    "elapsed_s",
    "wall_s",
    "started",
    "finished",
    "started_at",
    "finished_at",
    "duration_wall_s",
    "steps_per_s",
    "runtime_s",
}


def _h(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def _scrub(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _scrub(v) for k, v in obj.items() if k not in TIMING_KEYS and "wall" not in k}
    if isinstance(obj, list):
        return [_scrub(v) for v in obj]
    if isinstance(obj, str) and ("/tmp" in obj or tempfile.gettempdir() in obj):
        return "<tmp>"
    return obj


def _json_hash(path: Path) -> str:
    return _h(json.dumps(_scrub(json.loads(path.read_text())), sort_keys=True).encode())


def _mcap_hash(path: Path) -> str:
    from mcap.reader import make_reader

    h = hashlib.sha256()
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            h.update(channel.topic.encode())
            h.update((schema.name if schema else "").encode())
            h.update(message.log_time.to_bytes(8, "little"))
            h.update(message.data)
    return h.hexdigest()[:16]


def _agvsim(*args: str) -> None:
    subprocess.run(
        [sys.executable, "-m", "agvsim", *args], check=True, cwd=ROOT, stdout=subprocess.DEVNULL
    )


def single_runs(tmp: Path) -> dict[str, str]:
    out: dict[str, str] = {}
    files = sorted((ROOT / "scenarios").rglob("*.yaml"))
    for f in files:
        if "vda5050:" in f.read_text():
            continue
        rel = f.relative_to(ROOT).as_posix()
        d = tmp / rel.replace("/", "_")
        duration = "30" if "slam" in f.name else "12"
        _agvsim(
            "run", rel, "--out", str(d), "--duration", duration, "--seed", "3", "--no-plot", "-q"
        )
        out[f"run:{rel}:trajectory"] = _h((d / "trajectory.csv").read_bytes())
        out[f"run:{rel}:summary"] = _json_hash(d / "summary.json")
        out[f"run:{rel}:mcap"] = _mcap_hash(d / "run.mcap")
        print(f"  {rel}", file=sys.stderr)
    return out


def sweep_and_grade(tmp: Path) -> dict[str, str]:
    out: dict[str, str] = {}
    d = tmp / "sweep"
    _agvsim(
        "sweep",
        "examples/sweeps/avoid_speed_noise.yaml",
        "--out",
        str(d),
        "--limit",
        "6",
        "--no-plot",
        "-q",
        "--workers",
        "1",
    )
    import csv

    with (d / "results.csv").open() as f:
        rows = list(csv.DictReader(f))
    drop = ("wall", "real_time", "elapsed")
    lines = sorted(
        json.dumps({k: v for k, v in r.items() if not any(x in k for x in drop)}, sort_keys=True)
        for r in rows
    )
    out["sweep:results"] = _h("\n".join(lines).encode())
    g = tmp / "grade"
    _agvsim(
        "grade",
        "examples/grading/student_wall_follower.py",
        "--suite",
        "examples/grading/suite.yaml",
        "--out",
        str(g),
        "-q",
    )
    for name in ("grades.json",):
        if (g / name).exists():
            out[f"grade:{name}"] = _json_hash(g / name)
    print("  sweep, grade", file=sys.stderr)
    return out


def gym_rollouts() -> dict[str, str]:
    import gymnasium as gym

    import agvsim.gym  # noqa: F401  (registers the environments)

    out: dict[str, str] = {}
    for env_id in sorted(i for i in gym.registry if i.startswith("agvsim/")):
        if "Pursuit" in env_id:
            continue
        env = gym.make(env_id)
        env.action_space.seed(5)
        h = hashlib.sha256()
        obs, _ = env.reset(seed=11)
        h.update(np.asarray(obs, dtype=np.float64).tobytes())
        for _ in range(300):
            obs, rew, term, trunc, _ = env.step(env.action_space.sample())
            h.update(np.asarray(obs, dtype=np.float64).tobytes())
            h.update(np.float64(rew).tobytes())
            if term or trunc:
                obs, _ = env.reset()
                h.update(np.asarray(obs, dtype=np.float64).tobytes())
        env.close()
        out[f"gym:{env_id}"] = h.hexdigest()[:16]
    from agvsim.gym.pursuit_v0 import parallel_env

    env = parallel_env()
    obs, _ = env.reset(seed=4)
    h = hashlib.sha256()
    rng = np.random.default_rng(2)
    for _ in range(300):
        if not env.agents:
            obs, _ = env.reset(seed=5)
        actions = {
            a: rng.uniform(env.action_space(a).low, env.action_space(a).high).astype(
                env.action_space(a).dtype
            )
            for a in env.agents
        }
        obs, rew, term, trunc, _ = env.step(actions)
        for a in sorted(obs):
            h.update(np.asarray(obs[a], dtype=np.float64).tobytes())
            h.update(np.float64(rew[a]).tobytes())
    out["gym:pursuit_v0"] = h.hexdigest()[:16]
    print("  gym", file=sys.stderr)
    return out


def app_session() -> dict[str, str]:
    from agvsim.app.session import Session
    from agvsim.scenario import load_scenario

    out: dict[str, str] = {}
    s = Session(load_scenario(ROOT / "scenarios/thesis_maze_avoid.yaml"), "fingerprint")
    h = hashlib.sha256()

    def poses() -> None:
        st = s.sim.state
        h.update(np.ascontiguousarray(st.poses, dtype=np.float64).tobytes())

    s.step(100)
    poses()
    name = s.robot_names()[0]
    cfg = s.robot_config(name)
    s.apply_robot(name, cfg)
    s.step(50)
    poses()
    s.add_robot("mecanum", *s.free_spot(seed=1))
    s.step(80)
    poses()
    s.move_robot(s.robot_names()[-1], *s.free_spot(seed=2))
    s.step(60)
    poses()
    s.reset()
    s.step(40)
    poses()
    s.close()
    out["app:session"] = h.hexdigest()[:16]
    print("  app session", file=sys.stderr)
    return out


def fleet_in_process() -> dict[str, str]:
    from agvsim.master.run import InProcessRun
    from agvsim.scenario import load_scenario

    out: dict[str, str] = {}
    for name in ("warehouse_operations_differential.yaml", "warehouse_operations.yaml"):
        run = InProcessRun(load_scenario(ROOT / "scenarios" / name), seed=3, duration_s=90.0)
        run.run()
        h = hashlib.sha256(np.ascontiguousarray(run.fleet.sim.state.poses).tobytes())
        h.update(json.dumps(_scrub(run.summary()), sort_keys=True, default=str).encode())
        out[f"fleet:{name}"] = h.hexdigest()[:16]
    print("  fleet", file=sys.stderr)
    return out


def _prefixes(parts: set[str]) -> set[str]:
    names = {"runs": {"run"}, "sweep": {"sweep", "grade"}, "gym": {"gym"}, "app": {"app"}}
    return set().union(*(names.get(p, {p}) for p in parts))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="write the fingerprints here (JSON)")
    ap.add_argument("--compare", type=Path, help="compare with fingerprints written before")
    ap.add_argument("--only", default="", help="comma list of parts: runs,sweep,gym,app,fleet")
    args = ap.parse_args()
    parts = set(args.only.split(",")) if args.only else {"runs", "sweep", "gym", "app", "fleet"}
    fp: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        if "runs" in parts:
            fp.update(single_runs(tmp))
        if "sweep" in parts:
            fp.update(sweep_and_grade(tmp))
        if "gym" in parts:
            fp.update(gym_rollouts())
        if "app" in parts:
            fp.update(app_session())
        if "fleet" in parts:
            fp.update(fleet_in_process())
    if args.out:
        args.out.write_text(json.dumps(fp, indent=1, sort_keys=True) + "\n")
    if args.compare:
        before = json.loads(args.compare.read_text())
        if args.only:  # compare only the parts run now
            before = {k: v for k, v in before.items() if k.split(":")[0] in _prefixes(parts)}
        keys = sorted(set(before) & set(fp))
        diff = [k for k in keys if before[k] != fp[k]]
        missing = sorted(set(before) ^ set(fp))
        for k in diff:
            print(f"DIFFERS  {k}")
        for k in missing:
            print(f"ONLY ONE {k}")
        print(f"{len(keys) - len(diff)} of {len(keys)} fingerprints identical")
        return 1 if diff else 0
    print(json.dumps(fp, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
