"""
Step by step: a filter loop and iSAM2, scan by scan
===================================================

FilterPy users write their own loop: predict, update, store.  fgdoppler's
estimators can be driven the same way — :class:`~fgdoppler.estimators.ekf.ExtendedKalmanFilter`
takes one measurement at a time, :class:`~fgdoppler.estimators.isam2.ISAM2Tracker`
one scan (all pairs at one time) at a time — which is how a live system
feeds them.
"""

# %%
# A recording and its initiation
# ------------------------------
import matplotlib.pyplot as plt
import numpy as np

import fgdoppler as fd
from fgdoppler.estimators.ekf import ExtendedKalmanFilter
from fgdoppler.estimators.gaussian_sum import GaussianSumTracker
from fgdoppler.estimators.isam2 import ISAM2Tracker

scenario = fd.paper_scenario("b", 5e3)
sim = fd.simulate(scenario, np.random.default_rng(7))
model = fd.TrackingModel.of(scenario.geometry)
meas = sim.measurements
init = fd.initiate(meas.first_per_pair(10), model)
print(f"initiation window ends at t = {init.t_end} s, status {init.status}")
after = meas.subset(meas.time > init.t_end)

# %%
# The EKF, one measurement at a time
# ----------------------------------
# ``update`` predicts to the measurement's time (nothing to do when it equals
# the previous one) and applies the scalar update; it returns the normalised
# innovation squared (NaN when the gate rejects the measurement).
ekf = ExtendedKalmanFilter(model, init.x_end, init.P_end, init.t_end, fd.EKFSettings())
ekf_times, ekf_states = [], []
for t, pair, z, sigma in zip(after.time, after.pair, after.doppler, after.sigma, strict=True):
    nis = ekf.update(float(t), int(pair), float(z), float(sigma))
    if not ekf_times or ekf_times[-1] != t:
        ekf_times.append(float(t))
        ekf_states.append(ekf.x)
    else:
        ekf_states[-1] = ekf.x
print(f"EKF: {len(ekf_times)} scans, last NIS {nis:.2f}, final position σ "
      f"{np.sqrt(ekf.P[0, 0]):.1f} m (x), {np.sqrt(ekf.P[1, 1]):.1f} m (y)")

# %%
# iSAM2, one scan at a time
# -------------------------
# The first update adds the whole initiation window at once (two Doppler
# values cannot determine four unknowns; the window can), with the
# initiation's states as initial values.  Each later scan is one incremental
# update; ``add_scan`` returns the filtered state and covariance of the
# newest state, and ``finish`` solves the whole trajectory (the smoothed
# estimate).
window = meas.subset(meas.time <= init.t_end).scans()
wm = meas.subset(meas.time <= init.t_end)
guesses = model.motion.propagate(init.x_start, window.times - init.t_start)
tracker = ISAM2Tracker(model, fd.ISAM2Settings())
tracker.add_window(window.times, [wm.pair[window.rows(k)] for k in range(len(window))],
                   [wm.doppler[window.rows(k)] for k in range(len(window))],
                   [wm.sigma[window.rows(k)] for k in range(len(window))], guesses)
scans = after.scans()
isam_states = []
for k in range(len(scans)):
    rows = scans.rows(k)
    x, P = tracker.add_scan(scans.times[k], after.pair[rows], after.doppler[rows], after.sigma[rows])
    isam_states.append(x)
smoothed, smoothed_cov = tracker.finish()
print(f"iSAM2: {len(scans)} incremental updates, final filtered position σ {np.sqrt(P[0, 0]):.1f} m (x)")
print(f"iSAM2 finish: {len(smoothed)} smoothed states, first-state position σ "
      f"{np.sqrt(smoothed_cov[0][0, 0]):.1f} m (x) against {np.sqrt(init.P_start[0, 0]):.1f} m from the window alone")

# %%
# A live feed, with no initiation of your own
# -------------------------------------------
# Fed every scan from the first, with no window and no guess, the tracker
# *warms up*: it holds the scans of the first 4.5 s back (returning NaN and
# no covariance), initiates them by multi-start and adds them as one window,
# as ``fd.track`` does.  One scan per update from the model's broad prior
# would not hold: two Doppler values cannot place four unknowns, and each
# update is a single Gauss–Newton step.
live = ISAM2Tracker(model, fd.ISAM2Settings(), model.prior())
all_scans = meas.scans()
for k in range(len(all_scans)):
    rows = all_scans.rows(k)
    x_live, P_live = live.add_scan(all_scans.times[k], meas.pair[rows], meas.doppler[rows], meas.sigma[rows])
    if k == 0:
        print(f"first scan: state {x_live}, covariance {P_live}, warming up: {live.warming_up}")
assert P_live is not None
err_live = np.hypot(*(x_live - sim.truth.at(all_scans.times[-1:])[0])[:2])
print(f"live feed: final position error {err_live:.0f} m, stated σ {np.sqrt(P_live[0, 0] + P_live[1, 1]):.0f} m")

# %%
# A live feed that keeps every hypothesis
# ---------------------------------------
# The warmed-up tracker follows one Gaussian: the best solution of the first
# 4.5 s.  Where that window's posterior is a curved valley or has a mirror
# image, ``fd.track`` runs a tracker from each term of its Gaussian sum and
# weighs them by the later data; :class:`~fgdoppler.estimators.gaussian_sum.GaussianSumTracker`
# does the same scan by scan, and fed the same scans it gives ``fd.track``'s
# filtered estimates from the same initiation (without the restarts and the
# verdict, which need the whole recording).  ``mode`` is the heaviest
# hypothesis alone, ``weights`` the current weights.
# This recording is well observed: one hypothesis, and the Gaussian sum is
# the warmed-up tracker.  Case a from 5 km, near the baseline, is not: its
# first 4.5 s leave eight hypotheses.  One recording decides nothing (on
# this one both trackers end consistent, the single Gaussian nearer the
# truth); over many, the single Gaussian is the more often over-confident —
# docs/concepts.md, "Feeding a tracker yourself", has the numbers.


def live_feed(tracker, recording):
    """Every scan into ``tracker``; the last estimate, its error and its NEES."""
    m, sc = recording.measurements, recording.measurements.scans()
    for k in range(len(sc)):
        r = sc.rows(k)
        x, P = tracker.add_scan(sc.times[k], m.pair[r], m.doppler[r], m.sigma[r])
    d = x - recording.truth.at(sc.times[-1:])[0]
    return np.hypot(*d[:2]), float(d @ np.linalg.solve(P, d))


near = fd.simulate(fd.paper_scenario("a", 5e3), np.random.default_rng(7))
near_model = fd.TrackingModel.of(near.scenario.geometry)
single = ISAM2Tracker(near_model, fd.ISAM2Settings(), near_model.prior())
mixture = GaussianSumTracker(near_model, "isam2")
for label, trk in (("one Gaussian", single), ("Gaussian sum", mixture)):
    err_end, nees_end = live_feed(trk, near)
    print(f"case a, 5 km, {label}: final position error {err_end:.0f} m, NEES {nees_end:.1f}")
print(f"Gaussian sum: {len(mixture.weights)} hypotheses, final weights {np.round(mixture.weights, 3)}")

# %%
# The loops give what the one-call runners give
# ---------------------------------------------
# ``fd.run_estimator("ekf", ...)`` is this loop plus the verdict and, by
# default, the Gaussian sum over the initiation's hypotheses; with one
# component and no verification it is exactly the loop above.
one = fd.run_estimator("ekf", meas, model, init, fd.EKFSettings(components=1), verify=False).primary
print("largest difference to run_estimator:", float(np.max(np.abs(one.states[1:] - np.array(ekf_states)))), "m")

truth = sim.truth
err = {
    "EKF loop": np.hypot(*(np.array(ekf_states)[:, :2] - truth.at(ekf_times)[:, :2]).T),
    "iSAM2 filtered": np.hypot(*(np.array(isam_states)[:, :2] - truth.at(scans.times)[:, :2]).T),
}
fig, ax = plt.subplots(figsize=(7, 3.5), layout="constrained")
for label, e in err.items():
    ax.plot(ekf_times if label == "EKF loop" else scans.times, e, label=label)
t_all = np.asarray(tracker.times)
ax.plot(t_all, np.hypot(*(smoothed[:, :2] - truth.at(t_all)[:, :2]).T), label="iSAM2 smoothed (finish)")
ax.set_xlabel("time (s)")
ax.set_ylabel("position error (m)")
ax.legend()
