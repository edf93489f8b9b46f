"""Hypotheses that stop counting stop running: the mixture is the same as if they had run to the end."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
import fgdoppler.estimators.ambiguity as amb


def _case(s: int, r: int) -> tuple[fd.Measurements, fd.TrackingModel, fd.Initiation]:
    scen = fd.paper_scenarios()[s]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([2026, s, r])))
    model = fd.TrackingModel.of(scen.geometry)
    return sim.measurements, model, fd.initiate(sim.measurements.first_per_pair(10), model)


@pytest.mark.parametrize(("name", "settings"), [("isam2", fd.ISAM2Settings(restarts=False)),
                                                ("fixed-lag", fd.FixedLagSettings(restarts=False))])
@pytest.mark.parametrize(("s", "r"), [(2, 1), (5, 4)])
def test_stopped_hypotheses_leave_every_estimate_unchanged(monkeypatch: pytest.MonkeyPatch, name: str,
                                                           settings: fd.TrackerSettings, s: int, r: int) -> None:
    """Case a 45 km run 1 (a mirror hypothesis dies by 9 s) and case b 45 km run 4 (five of eight terms stop).

    With ``NEGLIGIBLE = 0`` nothing stops; a stopped hypothesis weighs below
    1e-12 wherever it is carried forward, so means move by less than 1e-12 of
    the hypotheses' spread (km: nanometres) and covariances by 1e-12 of its square.
    """
    m, model, init = _case(s, r)
    pruned = fd.run_estimator(name, m, model, init, settings, verify=False)
    assert any("stopped at" in e.message for e in pruned.events)
    monkeypatch.setattr(amb, "NEGLIGIBLE", 0.0)
    full = fd.run_estimator(name, m, model, init, settings, verify=False)
    assert not any("stopped at" in e.message for e in full.events)
    assert [e.kind for e in pruned.estimates] == [e.kind for e in full.estimates]
    for a, b in zip(pruned.estimates, full.estimates, strict=True):
        np.testing.assert_array_equal(a.times, b.times)
        np.testing.assert_array_equal(a.cov_ok, b.cov_ok)
        np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-6)
        np.testing.assert_allclose(a.covariances, b.covariances, rtol=1e-9, atol=1e-6)
    np.testing.assert_array_equal(pruned.hypothesis, full.hypothesis)
