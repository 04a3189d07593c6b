"""Kümmerle et al. relative-pose metric on a hand-worked trajectory, file errors, the CLI text."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from agvsim.slam.datasets import datasets_dir
from agvsim.slam.eval_cli import SlamCommandError, eval_command
from agvsim.slam.evaluate import (
    EvaluationError,
    EvaluationFormatError,
    evaluate_relations,
    format_relation_errors,
    load_relations,
    load_trajectory,
)

# poses at t = 10, 11, 12 s: origin, (1, 0) facing +y, (1, 1) facing -x
TRAJECTORY = """# timestamp x y theta
10.000000 0 0 0
11.000000 1 0 1.5707963267948966
12.000000 1 1 3.141592653589793
"""
# relation 1 exact; relation 2: est (1, 0, pi/2) vs true (1, 0.3, pi/2 + 0.1) -> 0.3 m, 0.1 rad;
# relation 3: est (1, 1, pi) vs true (1.4, 1.3, -pi + 0.05) -> 0.5 m, |wrap(2 pi - 0.05)| rad;
# relation 4: t2 = 13 is not in the trajectory; relation 2's t1 is 0.4 ms off (matched).
RELATIONS = """10.0 11.0 1.0 0.0 0 0 0 1.5707963267948966
11.0004 12.0 1.0 0.3 0 0 0 1.6707963267948966
10.0 12.0 1.4 1.3 0 0 0 -3.091592653589793
10.0 13.0 1.0 0.0 0 0 0 0.0
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_hand_worked_three_poses(tmp_path: Path) -> None:
    traj = load_trajectory(write(tmp_path, "traj.txt", TRAJECTORY))
    rel = load_relations(write(tmp_path, "r.relations", RELATIONS))
    res = evaluate_relations(traj, rel)
    assert res.count == 3 and res.n_relations == 4 and res.n_unmatched == 1
    np.testing.assert_array_equal(res.matched, [True, True, True, False])
    np.testing.assert_allclose(res.translation_error_m, [0.0, 0.3, 0.5], atol=1e-12)
    np.testing.assert_allclose(res.rotation_error_deg, np.degrees([0.0, 0.1, 0.05]), atol=1e-9)
    assert res.translation_mean_m == pytest.approx(0.8 / 3)
    assert res.translation_std_m == pytest.approx(np.std([0.0, 0.3, 0.5]))
    assert res.rotation_mean_deg == pytest.approx(math.degrees(0.05))
    text = format_relation_errors(res)
    assert "3 of 4" in text and "1 unmatched" in text and "0.2667" in text


def test_tolerance_excludes_far_timestamps(tmp_path: Path) -> None:
    traj = load_trajectory(write(tmp_path, "traj.txt", TRAJECTORY))
    rel = load_relations(write(tmp_path, "r.relations", RELATIONS))
    res = evaluate_relations(traj, rel, tolerance_s=1e-4)  # 0.4 ms is now too far
    np.testing.assert_array_equal(res.matched, [True, False, True, False])


def test_tum_trajectory_gives_same_result(tmp_path: Path) -> None:
    lines = []
    for t, x, y, th in np.loadtxt(write(tmp_path, "traj.txt", TRAJECTORY)):
        lines.append(f"{t} {x} {y} 0 0 0 {math.sin(th / 2)} {math.cos(th / 2)}")
    tum = load_trajectory(write(tmp_path, "traj.tum", "\n".join(lines)))
    rel = load_relations(write(tmp_path, "r.relations", RELATIONS))
    np.testing.assert_allclose(
        evaluate_relations(tum, rel).translation_error_m, [0.0, 0.3, 0.5], atol=1e-9
    )


def test_malformed_relations_line_names_file_and_line(tmp_path: Path) -> None:
    bad = RELATIONS.replace("10.0 12.0 1.4 1.3", "10.0 12.0 1.4 oops")
    path = write(tmp_path, "bad.relations", bad)
    with pytest.raises(EvaluationFormatError) as info:
        load_relations(path)
    assert info.value.line_no == 3
    assert "bad.relations:3" in str(info.value) and "oops" in str(info.value)
    assert "t1 t2 x y z roll pitch yaw" in str(info.value)


def test_malformed_trajectory_lines(tmp_path: Path) -> None:
    with pytest.raises(EvaluationFormatError, match=r"t\.txt:3: .*timestamp x y theta"):
        load_trajectory(write(tmp_path, "t.txt", "1 0 0 0\n\n2 0 0\n"))
    with pytest.raises(EvaluationFormatError, match=r":2: .*repeated timestamp"):
        load_trajectory(write(tmp_path, "t.txt", "1 0 0 0\n1 1 0 0\n"))
    with pytest.raises(EvaluationFormatError, match=r":1: "):
        load_trajectory(write(tmp_path, "t.txt", "1 0 nan 0\n"))
    with pytest.raises(EvaluationError, match="no data lines"):
        load_trajectory(write(tmp_path, "t.txt", "# nothing\n"))


def test_no_match_is_an_error(tmp_path: Path) -> None:
    traj = load_trajectory(write(tmp_path, "traj.txt", TRAJECTORY))
    rel = load_relations(write(tmp_path, "r.relations", "100 101 1 0 0 0 0 0\n"))
    with pytest.raises(EvaluationError, match="none of the 1 relations"):
        evaluate_relations(traj, rel)


def test_eval_command(tmp_path: Path) -> None:
    traj = write(tmp_path, "traj.txt", TRAJECTORY)
    rel = write(tmp_path, "r.relations", RELATIONS)
    text = eval_command(traj, rel)
    assert "traj.txt on r.relations" in text and "0.2667" in text
    with pytest.raises(SlamCommandError, match="not found"):
        eval_command(tmp_path / "missing.txt", rel)
    with pytest.raises(SlamCommandError, match=r"bad\.relations:1"):
        eval_command(traj, write(tmp_path, "bad.relations", "1 2 3\n"))


@pytest.mark.skipif(datasets_dir() is None, reason="datasets folder absent")
def test_intel_relations_load() -> None:
    root = datasets_dir()
    assert root is not None
    rel = load_relations(root / "intel" / "intel.relations")
    assert rel.t1_s.shape == (2984,)
