"""Mistakes in a measurement file named from windows later in the recording (fgdoppler.estimators.later_mistakes)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler.estimators.later_mistakes import MISTAKE_CODES, later_mistakes
from fgdoppler.estimators.verdict import Reason

#: A track's finding that its residuals fail the whole-track chi-square test, as the verdict writes it.
MISFIT = (Reason(code="fit", status="doubtful", message="the residuals fail the chi-square test"),)


def _paper(s: int, r: int) -> tuple[fd.Simulation, fd.TrackingModel]:
    scen = fd.paper_scenarios()[s]
    sim = fd.simulate(scen, np.random.default_rng(np.random.SeedSequence([2026, s, r])))
    return sim, fd.TrackingModel.of(scen.geometry)


def _negated(m: fd.Measurements) -> fd.Measurements:
    return fd.Measurements(time=m.time, pair=m.pair, doppler=-m.doppler, sigma=m.sigma)


@pytest.fixture(scope="module")
def negated() -> tuple[fd.Measurements, fd.TrackingModel, fd.Initiation, list[Reason], fd.TrackResult]:
    """Case a 25 km, run 0 (seed 2026) with every pair's Doppler negated: the recording, model, initiation, the
    later windows' finding for a track that misfits, and the EKF's result (``verify=False``)."""
    sim, model = _paper(1, 0)
    m = _negated(sim.measurements)
    init = fd.initiate(m.first_per_pair(10), model)
    return m, model, init, later_mistakes(m, model, init, MISFIT), fd.run_estimator("ekf", m, model, init,
                                                                                     verify=False)


def test_a_sign_the_initiation_window_fits_is_named_from_later_windows(
        negated: tuple[fd.Measurements, fd.TrackingModel, fd.Initiation, list[Reason], fd.TrackResult]) -> None:
    """Case a 25 km, run 0 (seed 2026) with every pair's Doppler negated.

    The initiation window of 10 measurements per pair is explained by a wrong
    track well enough that no negation makes it fit better (it names no
    mistake); 4.5 s windows later in the recording fit only with every pair
    negated, and the track that fails its residual test gets the finding.
    Through the registry (the EKF, its innovations failing the whole-track
    test) the finding is added and the status stays what the misfit made it.
    """
    m, model, init, found, result = negated
    assert not [r for r in init.reasons if r.code in MISTAKE_CODES]
    assert [(r.code, r.status) for r in found] == [("sign", "doubtful")]
    assert "with the Doppler of every pair negated the window fits" in found[0].message
    assert "negate the doppler column" in found[0].message and "of 3 windows" in found[0].message
    # a track that fits, or whose misfit is only informational, costs nothing and names nothing
    assert later_mistakes(m, model, init, ()) == []
    assert later_mistakes(m, model, init, (Reason(code="fit", status="ok", message="scale 0.3"),)) == []
    assert any(r.code == "fit" and r.status != "ok" for r in result.reasons)
    assert [r for r in result.reasons if r.code in MISTAKE_CODES] == found
    without = [r for r in result.reasons if r.code not in MISTAKE_CODES]
    assert result.status == fd.estimators.verdict.status_of(without)


@pytest.mark.parametrize("s", range(6))
def test_data_as_simulated_get_no_mistake_named_even_where_the_track_misfits(s: int) -> None:
    """The six paper scenarios, runs 0 and 1 as simulated, each told its track fails the residual test: the
    windows later in the recording fit as given, or fail with no change of sign or labels making them fit, so
    no mistake is named (a false finding would send the user to change correct data)."""
    for r in (0, 1):
        sim, model = _paper(s, r)
        init = fd.initiate(sim.measurements.first_per_pair(10), model)
        assert later_mistakes(sim.measurements, model, init, MISFIT) == []


def test_where_the_initiation_named_the_mistake_or_there_is_no_room_nothing_more_is_done() -> None:
    sim, model = _paper(2, 0)
    m = _negated(sim.measurements)
    init = fd.initiate(m.first_per_pair(10), model)
    assert [r.code for r in init.reasons if r.code in MISTAKE_CODES] == ["sign"]
    assert later_mistakes(m, model, init, MISFIT) == []
    short = m.between(0.0, init.t_end + 1.0)  # less than one window's span after the initiation window
    assert later_mistakes(short, model, init, MISFIT) == []
    with pytest.raises(ValueError, match="windows must be >= 1"):
        later_mistakes(m, model, init, MISFIT, windows=0)


def test_a_reference_that_made_the_same_check_gives_its_finding_and_saves_the_windows(
        negated: tuple[fd.Measurements, fd.TrackingModel, fd.Initiation, list[Reason], fd.TrackResult],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Case a 25 km run 0 negated, as above.  A reference track that misfits too, with the same ``huber_k``, has
    been through the same windows: its finding (here a planted one, to tell it from a recomputed one) is taken
    and no window is initiated.  With another ``huber_k``, another number of windows or a reference whose track
    fits, the windows are initiated again (here each refused, as a window no start explains, so that nothing
    is named).  Through the registry a filter held against such a reference initiates no window either, nor
    one given it without ``verify``; several estimators run together share the smoother's windows."""
    import fgdoppler.estimators.later_mistakes as module

    m, model, init, _, track = negated
    windows: list[float] = []

    def refused(window: fd.Measurements, *args: object, **kwargs: object) -> fd.Initiation:
        windows.append(float(window.time[0]))
        raise ValueError("no start in the zone explains the window")

    monkeypatch.setattr(module, "initiate", refused)
    planted = Reason(code="swapped", status="doubtful", message="planted")
    reference = replace(track, estimator="smoother", settings=fd.SmootherSettings(), reasons=(*MISFIT, planted))
    assert later_mistakes(m, model, init, MISFIT, reference=reference) == [planted] and windows == []
    for other, n in ((replace(reference, settings=fd.SmootherSettings(huber_k=1.5)), 3),
                     (replace(reference, reasons=(planted,)), 3), (reference, 2)):
        assert later_mistakes(m, model, init, MISFIT, windows=n, reference=other) == [] and len(windows) == n
        windows.clear()
    quick = fd.EKFSettings(sampled_covariance=False)  # its covariances do not matter here
    result = fd.run_estimator("ekf", m, model, init, quick, reference=reference)
    assert windows == [] and [r for r in result.reasons if r.code in MISTAKE_CODES] == [planted]
    # without verify a given reference serves the later windows alone, and several estimators share the smoother's
    result = fd.run_estimator("ekf", m, model, init, quick, verify=False, reference=reference)
    assert windows == [] and [r for r in result.reasons if r.code in MISTAKE_CODES] == [planted]
    both = fd.run_estimators(["smoother", "ekf"], m, model, init, {"ekf": quick}, verify=False)
    assert all(any(x.code == "fit" and x.status != "ok" for x in r.reasons) for r in both.values())
    assert len(windows) == 3


def test_the_change_that_makes_the_most_windows_pass_is_named_not_the_likeliest_in_one(
        negated: tuple[fd.Measurements, fd.TrackingModel, fd.Initiation, list[Reason], fd.TrackResult],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Planted per-window answers (case a 25 km run 0 negated gives the windows): the first window passes with
    pair 0 negated (cost 10) or pairs 0 and 1 exchanged (12), the second with every pair negated (9) or the same
    exchange (11), the third with none.  The likeliest change differs between the two windows, the exchange
    passes in both: it is named, from its first window, with that window's other change and its cost.  Among
    changes that pass in as many windows the least total cost wins."""
    import fgdoppler.estimators.later_mistakes as module
    from fgdoppler.estimators.window_mistakes import Mistake

    m, model, init, _, _ = negated
    sign0 = Mistake(code="sign", which="pair 0", cost=10.0, factor=-1.0)
    swap = Mistake(code="swapped", which="pairs 0 and 1", cost=12.0, factor=1.0)
    every = Mistake(code="sign", which="every pair", cost=9.0, factor=-1.0)
    answers = [replace(sign0, others=(swap,)), replace(every, others=(replace(swap, cost=11.0),)), None]
    monkeypatch.setattr(module, "find_mistake", lambda *args: answers.pop(0))
    found = later_mistakes(m, model, init, MISFIT)
    assert [r.code for r in found] == ["swapped"] and "2 of 3 windows" in found[0].message
    assert "with the labels of pairs 0 and 1 exchanged the window fits (cost 12.00" in found[0].message
    assert found[0].message.endswith("the window passes the same test with the Doppler of pair 0 negated "
                                     "(cost 10.00) too: check that change as well")
    # the exchange costs more in total than every pair negated when both pass in both windows
    answers[:] = [replace(every, cost=8.0, others=(swap,)), replace(swap, cost=11.0, others=(every,)), None]
    found = later_mistakes(m, model, init, MISFIT)
    assert [r.code for r in found] == ["sign"] and "with the Doppler of every pair negated the window fits (cost " \
        "8.00" in found[0].message
