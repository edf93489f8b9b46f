"""The initiation's factor callbacks, each against the path it replaced, alternately in one process.

* A measurement factor's callback: its state's pairs evaluated without re-checking them
  (:meth:`~fgdoppler.models.observation.DopplerModel.at_state`) against the checked model path, on the graph of
  an initiation window.
* The constant-velocity window factor's callback: its times and sensors laid out once, when it is built
  (:class:`~fgdoppler.models.doppler_kernels.Along`), against laying them out at every call (``_cv_along``),
  in Levenberg-Marquardt from each grid candidate of a window, with the zone wall, as the initiation runs it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

import fgdoppler as fd
from benchmarks._common import Row
from fgdoppler.estimators.initiation import lm_params, window_grid
from fgdoppler.factors import X, noise_model, region_factor
from fgdoppler.graphs import chain_graph, chain_values, cv_graph
from fgdoppler.models.doppler import StackedTimes, _cv_along
from fgdoppler.models.observation import DopplerModel


@dataclass(frozen=True)
class _Checked:
    """The Doppler model without ``at_state``: the factors fall back to ``predict`` and
    ``predict_and_jacobian``, which check their channels and take one state per row."""

    model: DopplerModel

    @property
    def n_channels(self) -> int:
        return self.model.n_channels

    @property
    def state_dim(self) -> int:
        return self.model.state_dim

    def predict(self, states: ArrayLike, channels: ArrayLike) -> NDArray[np.float64]:
        return self.model.predict(states, channels)

    def predict_and_jacobian(self, states: ArrayLike, channels: ArrayLike
                             ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return self.model.predict_and_jacobian(states, channels)


def _linearise_and_error(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> tuple[float, NDArray[np.float64]]:
    """What a Levenberg-Marquardt iteration asks of the graph: its error and its linearisation."""
    A, b = graph.linearize(values).jacobian()
    return float(graph.error(values)), np.concatenate([A.ravel(), b])


def _laid_out_per_call(t: NDArray[np.float64], tx: NDArray[np.float64], rx: NDArray[np.float64],
                       z: NDArray[np.float64], this: gtsam.CustomFactor, values: gtsam.Values,
                       jacobians: list[NDArray[np.float64]] | None) -> NDArray[np.float64]:
    """The window factor's callback before :class:`~fgdoppler.models.doppler_kernels.Along` (no Huber loss)."""
    g, J, _ = _cv_along(values.atVector(this.keys()[0]), t, tx, rx, jacobian=jacobians is not None)
    if jacobians is not None:
        jacobians[0] = np.ascontiguousarray(J)
    return g - z


def _window_refinement(repeat: int) -> Row:
    scen = fd.paper_scenario("a", 25e3)
    window = fd.simulate(scen, np.random.default_rng(1)).measurements.first_per_pair(10)
    model = fd.TrackingModel.of(scen.geometry)
    assert model.zone is not None
    order = window.stacked_order()
    times = StackedTimes(pair=window.pair[order], t=window.time[order] - window.time[0])
    z, sigma = window.doppler[order], window.sigma[order]
    tx, rx = scen.geometry.positions(2)
    wall = region_factor(X(0), model.zone)
    graphs = []
    for prepared in (True, False):
        if prepared:
            g, _ = cv_graph(scen.geometry, times, z, sigma, prior=model.prior())
        else:
            g = gtsam.NonlinearFactorGraph()
            g.add(gtsam.CustomFactor(noise_model(sigma), [X(0)], partial(
                _laid_out_per_call, times.t, tx[times.pair], rx[times.pair], z)))
            g.add(cv_graph(scen.geometry, times, z, sigma, prior=model.prior())[0].at(1))
        g.add(wall)
        graphs.append(g)
    starts = window_grid(window, model, fd.InitiationSettings()).states

    def refine(graph: gtsam.NonlinearFactorGraph) -> NDArray[np.float64]:
        out = []
        for x0 in starts:
            values = chain_values([x0])
            out.append(gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params()).optimize().atVector(X(0)))
        return np.array(out)

    times_: list[list[float]] = [[], []]
    outs: list[NDArray[np.float64]] = []
    for _ in range(repeat):
        outs = []
        for i, g in enumerate(graphs):
            t = time.process_time()
            for _ in range(5):
                out = refine(g)
            times_[i].append((time.process_time() - t) / 5)
            outs.append(out)
    same = np.array_equal(outs[0], outs[1])
    now, before = (float(np.median(ts)) for ts in times_)
    ratio = now / before
    return Row(name=f"initiation window refinement (case a 25 km, {len(window)} measurements): LM from each of "
                    f"{len(starts)} grid candidates on the constant-velocity window factor and the zone wall, "
                    "the factor's times and sensors laid out once vs at every call (the Doppler alone: the factor "
                    "before also checked its Jacobian at a higher cost)",
               value=f"{now * 1e3:.2f} ms vs {before * 1e3:.2f} ms CPU; "
                     + ("identical solutions" if same else "RESULTS DIFFER"),
               ratio=ratio, target="<= 0.9x, identical", met=same and ratio <= 0.9)


def run(repeat: int = 15) -> list[Row]:
    scen = fd.paper_scenario("a", 5e3)
    sim = fd.simulate(scen, np.random.default_rng(1))
    window = sim.measurements.first_per_pair(20)
    model = DopplerModel(geometry=scen.geometry)
    motion = fd.TrackingModel.of(scen.geometry).motion
    graphs = [chain_graph(window, m, motion)[0] for m in (model, _Checked(model))]
    values = chain_values(sim.truth.at(window.scans().times))
    times: list[list[float]] = [[], []]
    outs: list[tuple[float, NDArray[np.float64]]] = []
    for _ in range(repeat):
        outs = []
        for i, g in enumerate(graphs):
            t = time.process_time()
            for _ in range(20):
                out = _linearise_and_error(g, values)
            times[i].append((time.process_time() - t) / 20)
            outs.append(out)
    same = outs[0][0] == outs[1][0] and np.array_equal(outs[0][1], outs[1][1])
    now, before = (float(np.median(ts)) for ts in times)
    ratio = now / before
    return [Row(name=f"initiation window graph ({len(window.scans())} scans, {len(window)} measurements): "
                     "error and linearisation, pairs checked once vs at every call",
                value=f"{now * 1e3:.2f} ms vs {before * 1e3:.2f} ms CPU; "
                      + ("identical error and Jacobian" if same else "RESULTS DIFFER"),
                ratio=ratio, target="<= 0.8x, identical", met=same and ratio <= 0.8),
            _window_refinement(repeat)]


if __name__ == "__main__":
    for r in run():
        print(r)
