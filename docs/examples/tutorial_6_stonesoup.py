"""
fgdoppler and Stone Soup
========================

`Stone Soup <https://stonesoup.readthedocs.io>`_ has predictors, updaters,
particle filters, smoothers, metrics and plotting, but no bistatic Doppler
model.  ``fgdoppler.interop.stonesoup`` (extra ``fgdoppler[stonesoup]``:
``pip install 'fgdoppler[stonesoup]'``) supplies the model, turns fgdoppler's
measurements into Stone Soup detections, fgdoppler's initiation into a Stone
Soup prior, and tracks in either direction.  Nothing of Stone Soup is
imported unless this module is.

Two conventions differ and the bridge handles both:

* **state order** — Stone Soup's constant-velocity state is ``[x, vx, y, vy]``,
  fgdoppler's ``[x, y, vx, vy]``; ``TO_STONESOUP`` is the permutation (its own
  inverse);
* **time** — Stone Soup uses datetimes; fgdoppler seconds.  Every function
  takes an ``epoch`` (the datetime of t = 0).  Datetimes resolve microseconds,
  so ``to_track`` keeps the exact seconds in the track's metadata and
  ``from_track`` restores them.
"""

# %%
# Data, initiation and a Stone Soup prior
# ----------------------------------------
import datetime as dt

import numpy as np

import fgdoppler as fd
from fgdoppler.interop.stonesoup import detections, prior

scen = fd.paper_scenario("a", 45e3)                 # or your own geometry and CSV:
sim = fd.simulate(scen, np.random.default_rng(0))   # fd.Measurements.from_csv("measurements.csv")
model = fd.TrackingModel.of(scen.geometry)
init = fd.initiate(sim.measurements.first_per_pair(10), model)

epoch = dt.datetime(2026, 1, 1)
# one detection per scan: every pair measured at that time, one vector measurement
dets = [d for d in detections(sim.measurements, scen.geometry, epoch, per_scan=True)
        if d.metadata["time"] > init.t_end]
start = prior(init, epoch)          # GaussianState at the end of the initiation window
print(len(dets), "scans after the window; the prior at", start.timestamp.time())
print("model of the first scan:", dets[0].measurement_model.ndim_meas, "pairs")

# %%
# ``detections(..., per_scan=False)`` (the default) gives one scalar detection
# per measurement instead, each with its own pair's model: the form for
# asynchronous pairs and for Stone Soup's data association.  A filter that
# updates detection by detection, predicting over zero time between the
# pairs of a scan, is exactly fgdoppler's EKF with its gate off (equal to
# 1e-9 in fgdoppler's tests); with one detection per scan, as here, Stone
# Soup's EKF is fgdoppler's EKF with ``EKFSettings(update="scan")`` (one
# vector update per scan, also equal to 1e-9).  Stone Soup's Kalman smoothers
# need one prediction per time step, hence one detection per scan here.
#
# Stone Soup's filters and smoothers with fgdoppler's model
# ---------------------------------------------------------
from stonesoup.models.transition.linear import (
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.predictor.kalman import ExtendedKalmanPredictor, UnscentedKalmanPredictor
from stonesoup.predictor.particle import ParticlePredictor
from stonesoup.resampler.particle import ESSResampler
from stonesoup.smoother.kalman import ExtendedKalmanSmoother, UnscentedKalmanSmoother
from stonesoup.types.array import StateVectors
from stonesoup.types.hypothesis import SingleHypothesis
from stonesoup.types.state import ParticleState
from stonesoup.types.track import Track
from stonesoup.updater.kalman import ExtendedKalmanUpdater, UnscentedKalmanUpdater
from stonesoup.updater.particle import ParticleUpdater

from fgdoppler.interop.stonesoup import TO_STONESOUP

# the same continuous white-noise acceleration model: Stone Soup's ConstantVelocity(q) is fgdoppler's Q
q = model.motion.q
transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
sigma_points = {"alpha": 1.0, "beta": 2.0, "kappa": 0.0}

def run(predictor, updater, state):
    track = Track([state])
    for d in dets:
        state = updater.update(SingleHypothesis(predictor.predict(state, timestamp=d.timestamp), d))
        track.append(state)
    return track

ekf = run(ExtendedKalmanPredictor(transition), ExtendedKalmanUpdater(measurement_model=None), start)
ukf = run(UnscentedKalmanPredictor(transition, **sigma_points),
          UnscentedKalmanUpdater(measurement_model=None, **sigma_points), start)
ekf_rts = ExtendedKalmanSmoother(transition).smooth(ekf)
ukf_urts = UnscentedKalmanSmoother(transition, **sigma_points).smooth(ukf)

# a particle filter started from the same prior (particles drawn from it)
rng = np.random.default_rng(1)
cloud = rng.multivariate_normal(np.asarray(start.state_vector, dtype=float).ravel(),
                                np.asarray(start.covar, dtype=float), 5000)
particles = ParticleState(StateVectors(cloud.T), weight=np.full(5000, 1 / 5000), timestamp=start.timestamp)
np.random.seed(1)  # noqa: NPY002 -- Stone Soup's resampler draws from numpy's global generator
pf = run(ParticlePredictor(transition), ParticleUpdater(measurement_model=None, resampler=ESSResampler()),
         particles)
print(len(ekf), len(ukf_urts), len(pf), "states per track")

# %%
# fgdoppler's smoothers, compared with Stone Soup's metrics
# ---------------------------------------------------------
#
# fgdoppler's results become Stone Soup tracks (``to_track``), and the truth a
# ``GroundTruthPath``; Stone Soup's metric manager then scores every track the
# same way.  With one target and one track, the OSPA distance (p = 1, cut-off
# c) is the position error, capped at c.
from stonesoup.measures import Euclidean
from stonesoup.metricgenerator.manager import MultiManager
from stonesoup.metricgenerator.ospametric import OSPAMetric
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState

from fgdoppler.interop.stonesoup import to_track

smoother = fd.run_estimator("smoother", sim.measurements, model, init)
fixed_lag = fd.run_estimator("fixed-lag", sim.measurements, model, init)
truth = GroundTruthPath([GroundTruthState(x[TO_STONESOUP], timestamp=epoch + dt.timedelta(seconds=float(t)))
                         for t, x in zip(sim.truth.times, sim.truth.states, strict=True)])

def mean_ospa(track, t_from=5.0):
    manager = MultiManager([OSPAMetric(c=10e3, p=1, measure=Euclidean(mapping=(0, 2)))])
    manager.add_data({"tracks": {track}, "groundtruth_paths": {truth}})
    series = manager.generate_metrics()["ospa_generator"]["OSPA distances"].value
    return np.mean([m.value for m in series if (m.timestamp - epoch).total_seconds() >= t_from])

tracks = {"Stone Soup EKF": ekf, "Stone Soup UKF": ukf, "Stone Soup particle filter": pf,
          "Stone Soup EKF + RTS": ekf_rts, "Stone Soup UKF + URTS": ukf_urts,
          "fgdoppler fixed-lag": to_track(fixed_lag, epoch), "fgdoppler smoother": to_track(smoother, epoch)}
for name, track in tracks.items():
    print(f"{name:28s} mean OSPA over t >= 5 s: {mean_ospa(track):5.0f} m")

# %%
# One recording says little (the :doc:`accuracy benchmark </reproduction>`
# compares them over hundreds); the point here is that every track, from
# either library, is scored by the same code.
#
# Stone Soup's tracks in fgdoppler's metrics and plots
# ----------------------------------------------------
#
# ``from_track`` turns any Stone Soup track of Gaussian or particle states into
# an fgdoppler ``TrackResult``, so fgdoppler's NEES, verdict machinery and plots
# apply to Stone Soup's output.
import matplotlib.pyplot as plt

from fgdoppler.analysis.metrics import nees
from fgdoppler.interop.stonesoup import from_track
from fgdoppler.plotting import plot_track

urts = from_track(ukf_urts, epoch, estimator="stonesoup-urts", kind="smoothed").primary
truth_at = sim.truth.at(urts.times)
mean_nees = np.mean(nees(urts.states, urts.covariances, truth_at))
print(f"Stone Soup URTS: mean NEES {mean_nees:.1f} over {len(urts)} states (4 expected)")

fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
plot_track(urts.times, urts.states, scen.geometry, axes[0], covariances=urts.covariances,
           truth=truth_at, label="Stone Soup UKF + URTS")
ours = smoother.primary
plot_track(ours.times, ours.states, scen.geometry, axes[1], covariances=ours.covariances,
           truth=sim.truth.at(ours.times), label="fgdoppler smoother")

# %%
# Reference
# ---------
# :mod:`fgdoppler.interop.stonesoup`: ``BistaticDoppler`` (the measurement
# model, one pair or several), ``models``, ``detections`` and
# ``measurements_from``, ``prior``, ``to_track`` and ``from_track``.
