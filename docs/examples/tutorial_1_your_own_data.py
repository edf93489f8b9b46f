"""
Your own sensors and recording
==============================

A recording is two files: a **geometry** (TOML: the transmitter and receiver
of every pair, optionally the search zone) and a **measurement CSV**
(``time,pair,doppler,sigma``; Doppler as bistatic range rate in m/s, pairs
0-based; see :doc:`/data-formats`).  Here both are written for a layout that
is not the paper's — one transmitter, three receivers around a 40 km field —
and then read back and tracked as any user's files would be.
"""

# %%
# The geometry and the recording
# ------------------------------
# In practice these two files come from your system; here we write them.  The
# simulator stands in for the radar: a target at constant velocity, σ = 1 m/s.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import fgdoppler as fd
from fgdoppler.plotting import plot_track

folder = Path(tempfile.mkdtemp())
(folder / "geometry.toml").write_text("""\
# one transmitter, three receivers (positions in metres, any frame)
[[pair]]
tx = [20000.0, -15000.0]
rx = [0.0, 0.0]

[[pair]]
tx = [20000.0, -15000.0]
rx = [40000.0, 0.0]

[[pair]]
tx = [20000.0, -15000.0]
rx = [20000.0, 25000.0]
""")
truth_geometry = fd.Geometry.from_toml(folder / "geometry.toml")
scenario = fd.Scenario(geometry=truth_geometry, x0=(12e3, 8e3, 60.0, -25.0), duration=60.0, dt=0.5, sigma=1.0)
recording = fd.simulate(scenario, np.random.default_rng(4))
recording.measurements.to_csv(folder / "measurements.csv")
print((folder / "measurements.csv").read_text().splitlines()[:4])

# %%
# Reading the files
# -----------------
# ``Measurements.from_csv`` checks every row against the geometry (pair
# indices, sorted times, finite values) and names the file and line of the
# first problem.  The zone the initiation searches is derived from the sensors
# (:doc:`/concepts`); ``geometry.zone`` shows it.
geometry = fd.Geometry.from_toml(folder / "geometry.toml")
meas = fd.Measurements.from_csv(folder / "measurements.csv", geometry=geometry)
print(f"{len(meas)} measurements, {geometry.n_pairs} pairs, "
      f"t = {meas.time[0]:g}-{meas.time[-1]:g} s")
print("zone:", geometry.zone)

# %%
# A receiver that reports the Doppler shift in Hz
# ------------------------------------------------
# Passive radars and most receivers report the frequency shift
# :math:`f_D` of the transmitter's carrier, not the bistatic range rate.
# Give each pair's carrier wavelength :math:`\lambda = c / f_c` in the
# geometry (``wavelength = ...`` in every ``[[pair]]`` table) and the file
# may have the columns ``doppler_hz`` and ``sigma_hz``: they are read as the
# range rate :math:`-\lambda f_D` and its sigma :math:`\lambda \sigma_f`.  Here
# the transmitter is an FM station on 98.3 MHz; the same recording written
# in Hz reads back as the one in m/s, to rounding.
from dataclasses import replace

fm = replace(geometry, wavelengths=(fd.geometry.SPEED_OF_LIGHT / 98.3e6,) * geometry.n_pairs)
fm.to_toml(folder / "geometry_hz.toml")
(folder / "measurements_hz.csv").write_text(recording.measurements.csv_text(wavelengths=fm.wavelengths))
print((folder / "measurements_hz.csv").read_text().splitlines()[:2])
in_hz = fd.Measurements.from_csv(folder / "measurements_hz.csv", geometry=fd.Geometry.from_toml(folder / "geometry_hz.toml"))
print("largest difference from the m/s file:", np.max(np.abs(in_hz.doppler - meas.doppler)), "m/s")

# %%
# Initiation, then three estimators
# ---------------------------------
# The initiation fits the first 10 measurements of each pair and every
# measurement of the first 4.5 s (``initiation_window``: with fast data the
# span in time, not the count, fixes the start) by a grid search, then
# Levenberg–Marquardt from the best candidates.  The EKF and the
# fixed-lag smoother start from it; the offline smoother solves the whole
# recording.  Every result carries a verdict (``status``) and its reasons.
init = fd.initiate(meas.initiation_window(10, 4.5), geometry)
print("initiation:", init.status, "-", init.message)
results = {name: fd.run_estimator(name, meas, geometry, init) for name in ("ekf", "fixed-lag", "smoother")}
truth = recording.truth
for name, r in results.items():
    e = r.primary
    err = np.hypot(*(e.states[-1, :2] - truth.at(e.times[-1:])[0, :2]))
    sd = np.sqrt(np.max(np.linalg.eigvalsh(e.covariances[-1][:2, :2])))
    print(f"{name:10s} final error {err:6.1f} m, reported σ (major axis) {sd:6.1f} m, verdict {r.status}")
    for reason in r.reasons:
        if reason.status != "ok":
            print(f"    {reason.code}: {reason.message}")

# %%
# The tracks
# ----------
fig, axes = plt.subplots(1, 3, figsize=(13, 4), layout="constrained")
for ax, (name, r) in zip(axes, results.items(), strict=True):
    e = r.primary
    plot_track(e.times, e.states, geometry, ax, covariances=e.covariances, cov_ok=e.cov_ok,
                           truth=truth.at(e.times), label=name)
    ax.set_title(f"{name}: {r.status}", fontsize="small")

# %%
# A receiver that holds its last value
# ------------------------------------
# Some receivers repeat their last value when they have no detection, or
# write a fixed one (often 0).  Those rows are not measurements, and a track
# through them can be confidently wrong.  Noise makes two successive values
# equal only on a coarse grid, so every track tests each pair for values
# repeated more often than noise on the file's resolution allows and says so
# in a ``data`` finding; :func:`fgdoppler.repeats.drop_repeats` (``fgdoppler
# track --drop-repeats``) leaves them out.  Here pair 2 holds every fourth
# value.
from fgdoppler.repeats import drop_repeats, find_repeats

held = meas.doppler.copy()
rows = np.flatnonzero(meas.pair == 2)
held[rows[4::4]] = held[rows[3::4]][: rows[4::4].size]
stale = fd.Measurements(time=meas.time, pair=meas.pair, doppler=held, sigma=meas.sigma)
stale_track = fd.track(stale, geometry, "smoother")
print("held values:", stale_track.status)
for reason in stale_track.reasons:
    if reason.code == "data":
        print("   ", reason.message[:160], "...")
print(find_repeats(stale))
kept = drop_repeats(stale)
print(f"{len(stale) - len(kept)} repeats left out:", fd.track(kept, geometry, "smoother").status)

# %%
# Writing the result
# ------------------
# ``to_csv`` writes time, state and the covariance's upper triangle;
# ``to_json`` adds the settings, verdict and events.  The command line does
# the same: ``fgdoppler track measurements.csv --geometry geometry.toml
# --estimator smoother --out track.csv``.
results["smoother"].to_csv(folder / "track.csv")
print((folder / "track.csv").read_text().splitlines()[0])
