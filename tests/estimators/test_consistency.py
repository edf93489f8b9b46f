"""EKF consistency over 200 seeded runs of case (a) at 45 km (slow: run with ``pytest -m slow``).

Measured (seed 7, q = 1e-3, 2026-11-28): the run-averaged NEES from 10 s on is 4.04-4.44 over
time (mean 4.27) against the 95 % band [3.62, 4.40] of one time, outside it at 6 of the 41
times (13.5-15.5 s and 17.5 s: the NEES of one run is strongly correlated over time, 0.95 from one
scan to the next, 0.67 ten scans apart); the median NEES is 3.3-3.9 and no run diverges.  Over
the runs the time-averaged NEES has a 95 % interval of 3.93-4.60 for its mean, which holds the
state dimension 4: the data do not show the filter overconfident at that level
(:func:`test_ekf_mean_nees_is_the_state_dimension`).  Before the registry checked the EKF's
covariances against posterior samples (``EKFSettings.sampled_covariance``, 2026-11-24) the
mean was 4.96 (4.6-5.3 over time): with today's spread over the runs (±0.33) its interval would
not hold 4 (the old runs' spread was not kept, so this is an estimate).  Before ambiguous
initiations were resolved and the initiation covariance left out the region wall, run 117
reached 1e6.  The band test at every time is an expected failure, kept strict so that it
reports when every time's average falls inside the band.
"""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.analysis.metrics import nees, nees_band
from fgdoppler.estimators import run_estimator
from fgdoppler.estimators.initiation import initiate
from fgdoppler.models.observation import DopplerModel


def _ekf_nees(n_runs: int = 200, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    sc = fd.paper_scenario("a", 45e3)
    model = DopplerModel(geometry=sc.geometry)
    out = []
    for seq in np.random.SeedSequence(seed).spawn(n_runs):
        sim = fd.simulate(sc, np.random.default_rng(seq))
        init = initiate(sim.measurements.first_per_pair(10), sc.geometry)
        r = run_estimator("ekf", sim.measurements, model, init).primary
        out.append(nees(r.states, r.covariances, sim.truth.at(r.times)))
    return r.times, np.array(out)


@pytest.fixture(scope="module")
def ekf_nees() -> tuple[np.ndarray, np.ndarray]:
    return _ekf_nees()


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="NEES 4.04-4.44 over time: above the band [3.62, 4.40] at 6 of 41 correlated times "
                   "(see module doc)")
def test_ekf_average_nees_inside_95_band(ekf_nees: tuple[np.ndarray, np.ndarray]) -> None:
    t, n = ekf_nees
    lo, hi = nees_band(n.shape[0])
    m = n.mean(axis=0)[t >= 10.0]
    assert np.all((m >= lo) & (m <= hi))


@pytest.mark.slow
def test_ekf_mean_nees_is_the_state_dimension(ekf_nees: tuple[np.ndarray, np.ndarray]) -> None:
    """The mean NEES over runs and times from 10 s on is the state dimension within its 95 % interval.

    Each run's NEES averaged over its times is one sample (the times of a run are correlated, the
    runs independent); the Student-t interval of their mean over the 200 runs must hold 4.
    """
    from scipy.stats import t as student

    t, n = ekf_nees
    per_run = n[:, t >= 10.0].mean(axis=1)
    half = student.ppf(0.975, per_run.size - 1) * per_run.std(ddof=1) / np.sqrt(per_run.size)
    assert abs(per_run.mean() - 4.0) <= half, (per_run.mean(), half)


@pytest.mark.slow
def test_ekf_does_not_diverge_and_median_nees_is_consistent(ekf_nees: tuple[np.ndarray, np.ndarray]) -> None:
    t, n = ekf_nees
    sel = t >= 10.0
    assert np.all(n[:, sel] < 100.0)  # no run diverges
    med = np.median(n[:, sel], axis=0)
    # median of chi2_4 is 3.36; 200 runs give it a standard error of about 0.25
    assert np.all((med > 2.5) & (med < 5.0))
