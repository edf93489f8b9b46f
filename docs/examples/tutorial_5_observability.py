"""
Observability for system design
===============================

Before placing sensors: where, and for which tracks, does Doppler alone
determine a target?  The paper's measure :math:`O(\\mathbf x_0) =
\\log_{10}\\det(\\mathbf J^\\top\\mathbf J)` (Eq. 18; :math:`\\mathbf J` the
Jacobian of all of a window's Doppler values with respect to the initial
state, unit noise) is large where the window pins the state down and falls
to the −40 floor where it cannot.  This tutorial compares the paper's case
(a) — two pairs nearly on one line — with the same transmitters moved 8 km
off the baseline.
"""

# %%
# Two layouts
# -----------
import matplotlib.pyplot as plt

import fgdoppler as fd
from fgdoppler.analysis.observability import geometry_speed_table, observability_map
from fgdoppler.plotting import plot_geometry, plot_observability_map

paper = fd.paper_geometry("a")
moved = fd.Geometry(pairs=(fd.BistaticPair(tx=(50e3, 8e3), rx=(0.0, 0.0)),
                           fd.BistaticPair(tx=(50e3, -8e3), rx=(0.0, 0.0))), name="transmitters 8 km off")
fig, axes = plt.subplots(1, 2, figsize=(11, 3.5), layout="constrained")
for ax, g, title in ((axes[0], paper, "paper, case (a)"), (axes[1], moved, "transmitters 8 km off")):
    plot_geometry(g, ax)
    ax.set_title(title, fontsize="small")

# %%
# Maps of O over start position and heading
# -----------------------------------------
# Targets 2 km across the first baseline at 100 m/s, every start along it and
# every heading, with the sampling of the paper's Table 2 (printed below).
# Positions and headings are in each geometry's own frame.
maps = {name: observability_map(g, y=2e3, speed=100.0) for name, g in (("paper", paper), ("moved", moved))}
fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
for ax, (name, m) in zip(axes, maps.items(), strict=True):
    plot_observability_map(m, ax, title=name)
print("sampling:", maps["paper"].sampling)
for name, m in maps.items():
    print(f"{name:6s}: O from {m.O.min():.1f} to {m.O.max():.1f}; "
          f"{m.unobservable.mean():.1%} of the (start, heading) cells at the floor")

# %%
# Table 2 for both layouts
# ------------------------
# The paper's Table 2: the largest and smallest O over the map, per speed.
# Slower targets give less Doppler geometry change in the window, hence less
# information.
for g in (paper, moved):
    print(geometry_speed_table(g, y=2e3).to_markdown())
    print()
