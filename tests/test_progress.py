"""Progress reporting: every task counted to its total, answers unchanged, nothing drawn off a terminal."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.cli import main
from fgdoppler.estimators.ambiguity import resolve
from fgdoppler.estimators.ekf import run_ekf
from fgdoppler.estimators.settings import EKFSettings
from fgdoppler.progress import TqdmProgress


class Recorder:
    """A Progress that records ``[name, total, steps]`` per task."""

    def __init__(self) -> None:
        self.tasks: list[list] = []

    def task(self, name: str, total: int | None) -> None:
        self.tasks.append([name, total, 0])

    def advance(self, n: int = 1) -> None:
        assert self.tasks, "advance before any task"
        self.tasks[-1][2] += n


@pytest.fixture(scope="module")
def case_b() -> tuple[fd.Simulation, fd.Initiation]:
    sc = fd.paper_scenario("b", 5e3)
    sim = fd.simulate(sc, np.random.default_rng(1))
    return sim, fd.initiate(sim.measurements.first_per_pair(10), sc.geometry)


@pytest.mark.parametrize("name", list(fd.ESTIMATORS))
def test_every_estimator_counts_each_task_to_its_total(case_b, name: str) -> None:
    sim, init = case_b
    geometry = sim.scenario.geometry
    rec = Recorder()
    with_progress = fd.run_estimator(name, sim.measurements, geometry, init, progress=rec)
    plain = fd.run_estimator(name, sim.measurements, geometry, init)
    for est_a, est_b in zip(with_progress.estimates, plain.estimates, strict=True):
        np.testing.assert_array_equal(est_a.states, est_b.states)  # reporting changes nothing
    assert rec.tasks, "no progress reported"
    n_after_window = len(sim.measurements.between(init.t_end + 1e-9, np.inf).scans())
    for task_name, total, steps in rec.tasks:
        if total is not None:
            assert steps == total, task_name
        else:
            assert steps >= 1, task_name
    names = [t[0] for t in rec.tasks]
    if name == "smoother":
        lm = [t for t in rec.tasks if t[0] == "smoother: Levenberg-Marquardt"]
        assert len(lm) == 1 and lm[0][2] == with_progress.iterations
        # the split test of the motion model: the whole recording and its two halves, nothing simulated (no finding)
        assert [t[1:] for t in rec.tasks if t[0] == "smoother: split test of the motion model"] == [[None, 3]]
        assert "manoeuvre" not in [r.code for r in with_progress.reasons]
    else:
        own = rec.tasks[0]
        assert own[0] == name
        # the window is one step of the streaming trackers; the EKF and the particle estimators start after it
        assert own[1] == n_after_window + (0 if name in ("ekf", "particle", "map") else 1)
        assert any(n.startswith("reference: smoother") for n in names)  # the verdict's reference run


def test_the_split_tests_simulated_recordings_are_counted() -> None:
    # Where the split statistic exceeds its chi-square level, recordings simulated under the model are split and
    # fitted too (manoeuvre.simulated_scale): three fits for the data and three for each of 4 to 16 of them, each
    # a step of the one task, so that a long recording's check is seen to move.
    from fgdoppler.estimators.manoeuvre import MIN_REPLICATES, REPLICATES
    from tests.estimators.test_manoeuvre import _manoeuvring_two_pair_recording

    g, sim = _manoeuvring_two_pair_recording(4)
    m = sim.measurements
    rec = Recorder()
    res = fd.run_estimator("smoother", m, g, fd.initiate(m.first_per_pair(10), g), progress=rec, verify=False)
    assert [r.status for r in res.reasons if r.code == "manoeuvre"] == ["doubtful"]
    # an ambiguous initiation: the hypotheses' smoothers run apart and the best one's findings are made once
    [(total, steps)] = [t[1:] for t in rec.tasks if t[0].endswith("smoother: split test of the motion model")]
    assert total is None and steps % 3 == 0 and 3 + 3 * MIN_REPLICATES <= steps <= 3 + 3 * REPLICATES, steps


def test_hypotheses_are_named(case_b) -> None:
    sim, init = case_b
    rec = Recorder()
    model = fd.TrackingModel.of(sim.scenario.geometry)
    resolve(run_ekf, "likelihood", sim.measurements, model, [init, init], EKFSettings(), rec)
    assert [t[0] for t in rec.tasks] == ["hypothesis 1/2: ekf", "hypothesis 2/2: ekf"]


def test_tqdm_bars_only_where_asked() -> None:
    quiet = io.StringIO()  # not a terminal: nothing drawn
    with TqdmProgress(file=quiet) as bar:
        bar.task("work", 10)
        bar.advance(10)
    assert quiet.getvalue() == ""
    shown = io.StringIO()
    with TqdmProgress(file=shown, disable=False) as bar:
        bar.task("work", 10)
        bar.advance(10)
    assert "work" in shown.getvalue()


def test_track_on_a_pipe_prints_no_bar(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim"
    assert main(["simulate", "--case", "b", "--start-x", "5000", "--seed", "3", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["track", str(out / "measurements.csv"), "--estimator", "isam2"]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err and "isam2 final smoothing" not in err
