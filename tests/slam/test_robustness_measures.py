"""The robustness suite's measure for thinned logs (benchmarks/bench_slam_robustness.py,
``kept_ratio``), on trajectories whose errors are worked out by hand."""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import numpy as np
import pytest

from agvsim.slam.evaluate import Relations, Trajectory, evaluate_relations

ROOT = Path(__file__).resolve().parents[2]


def _bench():  # type: ignore[no-untyped-def]
    """The benchmark as a module. Imported, it must leave NUMBA_NUM_THREADS alone: numba
    refuses a value that differs from the threads it already launched (a fresh clone's CI
    failed 18 tests after this module set it once)."""
    before = os.environ.get("NUMBA_NUM_THREADS")
    spec = importlib.util.spec_from_file_location(
        "bench_slam_robustness", ROOT / "benchmarks" / "bench_slam_robustness.py"
    )
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    assert os.environ.get("NUMBA_NUM_THREADS") == before
    return mod


def _line(t: np.ndarray, speed: float) -> np.ndarray:
    return np.column_stack([speed * t, np.zeros_like(t), np.zeros_like(t)])


def test_kept_ratio_scores_every_relation_between_the_kept_scans() -> None:
    """Truth drives 1 m/s along x, scans at 10 Hz for 10 s, each scan related to the one 1 s
    later (91 relations). The unperturbed run reads 1.1 m/s (0.1 m off per relation), the
    thinned run keeps one scan a second but not those at 4 and 5 s and reads 1.2 m/s (0.2 m
    off): a 3 s gap, so the 39 relations with an end strictly between 3 and 6 s are left out
    (t1 = 2.1 ... 5.9 s); 52 remain, and motion on a line interpolates exactly: ratio 2."""
    b = _bench()
    t = np.arange(101) * 0.1
    rel = Relations(t[:91], t[10:], np.tile([1.0, 0.0, 0.0], (91, 1)))
    kept = np.array([k for k in range(0, 101, 10) if k not in (40, 50)])
    ratio, n, read = b.kept_ratio(t[kept], _line(t[kept], 1.2), t, _line(t, 1.1), rel)
    assert n == 52
    assert ratio == pytest.approx(2.0, rel=1e-9)
    assert read == pytest.approx(0.1, rel=1e-9)
    # only the scans both kept count: a wider gap leaves nothing but the exact ends
    assert b.kept_ratio(t[kept], _line(t[kept], 1.2), t, _line(t, 1.1), rel, 0.5)[:2] == (
        pytest.approx(2.0, rel=1e-9),
        7,  # 0-1, 1-2, 2-3, 6-7, 7-8, 8-9, 9-10 s
    )


def test_kept_ratio_charges_the_interpolation_to_both_runs() -> None:
    """On a circle (1 m radius, 0.5 rad/s) a chord between kept scans 1 s apart misses the
    arc, so reading poses between them is wrong (the unperturbed run, 2 mm off per pose, is
    off by over twice its own error when read that way); a thinned run whose kept poses are
    exactly the unperturbed run's scores 1, however wrong the interpolation."""
    b = _bench()
    t = np.arange(101) * 0.1
    truth = np.column_stack([np.cos(0.5 * t), np.sin(0.5 * t), 0.5 * t + np.pi / 2])
    from agvsim.slam.se2 import between

    rel = Relations(t[:95], t[6:], between(truth[:95], truth[6:]))
    noisy = truth + np.random.default_rng(0).normal(0.0, 0.002, truth.shape)
    kept = np.arange(0, 101, 10)
    ratio, n, read = b.kept_ratio(t[kept], noisy[kept], t, noisy, rel)
    assert n == 95
    assert ratio == pytest.approx(1.0, abs=1e-12)
    # the chords: the unperturbed run read between its kept scans is far off
    exact = evaluate_relations(Trajectory(t, noisy), rel).translation_mean_m
    assert read > 2.0 * exact


def test_faults_combine_with_plus_and_a_wrong_one_is_named(
    capsys: pytest.CaptureFixture[str],
) -> None:
    bench = _bench()
    assert bench.fault_spec("scale+thin") == "scale+thin"
    assert bench.fault_spec("none") == "none"
    with pytest.raises(SystemExit):
        bench.main(["--faults", "scale+fast", "--logs"])
    err = capsys.readouterr().err
    assert "fault 'fast' in 'scale+fast'" in err and "freeze-turn" in err


def test_slam_fields_are_overridden_for_an_a_b_run_and_a_wrong_one_is_named(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``--slam scale_pairs=None`` (the old scale estimate) is taken; a field SlamConfig
    lacks, or a value that is no literal, is refused with the option's name."""
    bench = _bench()
    assert bench.main(["--slam", "scale_pairs=None", "--logs", "--faults", "none"]) == 0
    for bad in ("no_such_field=1", "scale_pairs=off"):
        with pytest.raises(SystemExit):
            bench.main(["--slam", bad, "--logs"])
        err = capsys.readouterr().err
        assert "--slam" in err and bad.split("=")[0] in err


def test_pass_stamps_drive_the_log_there_and_back() -> None:
    # a log stamped 10, 11, 13 (span 3 + 0.1 s): the second pass runs the scans backwards
    # mirrored about 13 and 0.1 s after it (13.1, 15.1, 16.1), the third forwards one span
    # after the first's stamps (16.2, 17.2, 19.2); the fourth mirrors again
    bench = _bench()
    t, k = bench.pass_stamps(np.array([10.0, 11.0, 13.0]), 4)
    np.testing.assert_allclose(t[:9], [10, 11, 13, 13.1, 15.1, 16.1, 16.2, 17.2, 19.2])
    np.testing.assert_allclose(t[9:], [19.3, 21.3, 22.3])
    assert k.tolist() == [0, 1, 2, 2, 1, 0, 0, 1, 2, 2, 1, 0]
    assert np.all(np.diff(t) > 0)
    t1, k1 = bench.pass_stamps(np.array([10.0, 11.0, 13.0]), 1)
    assert t1.tolist() == [10.0, 11.0, 13.0] and k1.tolist() == [0, 1, 2]
