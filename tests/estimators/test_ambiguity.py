"""Hypotheses that stop counting stop running: the mixture is the same as if they had run to the end."""

from __future__ import annotations

import numpy as np
import pytest

import fgdoppler as fd
import fgdoppler.estimators.ambiguity as amb
from fgdoppler.estimators.smoother_modes import MODES_PER_PAIR
from tests.conftest import benchmark_run


def _case(s: int, r: int) -> tuple[fd.Measurements, fd.TrackingModel, fd.Initiation]:
    sim, model, init = benchmark_run(s, r)
    return sim.measurements, model, init


def _assert_same_report(judged: fd.TrackResult, alone: fd.TrackResult) -> None:
    """``run_estimator``'s smoother and ``alone``, resolved by hand, report the same to the bit."""
    from benchmarks.bench_mode_search import same_findings

    a, b = judged.primary, alone.primary
    np.testing.assert_array_equal(a.states, b.states)
    np.testing.assert_array_equal(a.covariances, b.covariances)
    assert judged.cost == alone.cost
    assert same_findings(judged, alone)
    assert [e.message for e in judged.events] == [e.message for e in alone.events]


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


def test_the_smoothers_of_the_hypotheses_search_the_recording_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Case a 45 km run 1 (two hypotheses): the whole-recording mode search is the same for both.

    Through the registry each whole-recording grid (named here by the
    measurements it scores) runs once for the two hypotheses' smoothers (a
    :class:`~fgdoppler.estimators.search_memo.SearchMemo`); resolved without
    the memo the same grids run, the mode search's once per hypothesis.  The
    track, its covariances, cost, findings and events are the same to the bit.
    """
    import fgdoppler.estimators.initiation as initiation
    from fgdoppler.estimators.registry import ESTIMATORS, hypotheses_of

    m, model, init = _case(2, 1)
    settings = fd.SmootherSettings(sampled_covariance=False)
    hyps, weights = hypotheses_of("smoother", m, model, init, settings)
    assert len(hyps) == 2
    grids: list[int] = []
    counted = initiation.window_grid

    def counting(scored: fd.Measurements, *args: object, **kwargs: object) -> object:
        grids.append(len(scored))
        return counted(scored, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(initiation, "window_grid", counting)
    shared = fd.run_estimator("smoother", m, model, init, settings, verify=False)
    with_memo = sorted(grids)
    grids.clear()
    alone = amb.resolve(ESTIMATORS["smoother"].run, "cost", m, model, hyps, settings, None, weights)
    assert with_memo and with_memo == sorted(set(grids)) and len(grids) > len(with_memo)
    assert grids.count(2 * MODES_PER_PAIR) == 2  # the mode search's grid, two pairs: once per hypothesis
    _assert_same_report(shared, alone)


def test_a_search_memo_serves_one_recording() -> None:
    from fgdoppler.estimators.search_memo import SearchMemo

    m, _, _ = _case(2, 1)
    memo = SearchMemo(m)
    calls: list[str] = []

    def search(name: str) -> list[np.ndarray]:
        calls.append(name)
        return [np.full(4, len(calls), dtype=float)]

    first = memo.starts(m, "k", lambda: search("first"))
    again = memo.starts(m, "k", lambda: search("again"))
    other = memo.starts(m, "other", lambda: search("other"))
    assert calls == ["first", "other"] and again is first and other[0][0] == 2.0
    with pytest.raises(ValueError, match="one recording"):
        memo.starts(m.first_per_pair(10), "k", list)


def test_only_the_hypothesis_of_lowest_cost_is_finished(monkeypatch: pytest.MonkeyPatch) -> None:
    """Case b 25 km run 0 (two hypotheses, a skewed posterior): the registry finishes one smoother run.

    Through the registry (:func:`~fgdoppler.estimators.ambiguity.resolve_staged`)
    the posterior samples of the reported covariances are drawn for the
    hypothesis of lowest cost only; each hypothesis run whole draws them for
    both.  The track reported, its covariances, cost, findings and events are
    the same to the bit.
    """
    import fgdoppler.estimators.smoother as smoother
    from fgdoppler.estimators.registry import ESTIMATORS, hypotheses_of

    m, model, init = _case(4, 0)
    settings = fd.SmootherSettings()
    hyps, weights = hypotheses_of("smoother", m, model, init, settings)
    assert len(hyps) == 2
    sampled: list[bool] = []
    drawn = smoother.posterior_spread

    def counting(*args: object, **kwargs: object) -> object:
        out = drawn(*args, **kwargs)  # type: ignore[arg-type]
        sampled.append(out is not None)
        return out

    monkeypatch.setattr(smoother, "posterior_spread", counting)
    staged = fd.run_estimator("smoother", m, model, init, settings, verify=False)
    assert sampled == [True]
    sampled.clear()
    whole = amb.resolve(ESTIMATORS["smoother"].run, "cost", m, model, hyps, settings, None, weights)
    assert sampled == [True, True]
    _assert_same_report(staged, whole)


@pytest.mark.parametrize("name", ["ekf", "isam2"])
def test_a_hypothesis_of_zero_weight_takes_no_share(name: str) -> None:
    """Case a 45 km run 1 (a mirror hypothesis): prior weights (1, 0) report the first hypothesis's run alone.

    A restart's running estimate can weigh exactly zero, its share of the
    window's posterior underflowing (a random layout at 5 Hz); its log
    weight is then -inf, so every mixture weight is exactly (1, 0) and the
    mixed means are the first run's to the bit (pytest turns the log's
    divide-by-zero warning into an error).  Weights that are not one finite,
    non-negative number per hypothesis, or all zero, are refused before
    anything runs.
    """
    m, model, init = _case(2, 1)
    hyps = amb.hypotheses(init)
    assert len(hyps) == 2
    info = fd.ESTIMATORS[name]
    settings = info.settings(restarts=False)
    mixed = amb.resolve(info.run, "likelihood", m, model, hyps, settings, None, np.array([1.0, 0.0]))
    alone = info.run(m, model, hyps[0], settings)
    np.testing.assert_array_equal(mixed.primary.times, alone.primary.times)
    np.testing.assert_array_equal(mixed.primary.states, alone.primary.states)
    np.testing.assert_allclose(mixed.primary.covariances, alone.primary.covariances, rtol=1e-12, atol=0)
    for bad in ([0.0, 0.0], [1.0, -0.5], [1.0, np.inf], [1.0, np.nan], [1.0]):
        with pytest.raises(ValueError, match="non-negative"):
            amb.resolve(info.run, "likelihood", m, model, hyps, settings, None, np.array(bad))


def test_a_lagged_estimate_is_weighted_by_the_data_it_has_read() -> None:
    """The fixed-lag smoother's lagged mixture at ``t`` is what the data up to ``t + lag`` give.

    Each hypothesis's lagged estimate at ``t`` was smoothed by the scans up
    to ``t + lag``; its weight in the mixture must be too, or the
    lagged track would answer from the whole recording.  Case a 5 km run 0
    (eight terms whose weights move with the later data): cut the recording
    at ``T`` and every lagged state up to ``T - lag`` is the full
    recording's (restarts on: their checkpoints before ``T`` are the same;
    hypotheses stopped after ``T`` weigh < 1e-12, so means agree to far
    below a micrometre of their kilometre spread; measured: equal to the
    bit).  Weighed with the final weights, as before, they differed by
    up to 130 m.
    """
    m, model, init = _case(0, 0)
    settings = fd.FixedLagSettings(sampled_covariance=False)
    T = 20.0

    def run(data: fd.Measurements) -> fd.TrackResult:
        return fd.run_estimator("fixed-lag", data, model, init, settings, verify=False)

    full, cut = run(m), run(m.subset(m.time <= T))
    a, b = full.estimate("lagged"), cut.estimate("lagged")
    early = a.times <= T - settings.lag - 1e-9
    assert np.count_nonzero(early) > 20
    np.testing.assert_array_equal(a.times[early], b.times[:np.count_nonzero(early)])
    np.testing.assert_allclose(b.states[:np.count_nonzero(early)], a.states[early], rtol=0, atol=1e-6)
    # the weights do move with the data: the heaviest hypothesis changes along these estimates (0, 3, 5)
    assert len(set(full.hypothesis[early].tolist())) >= 2
