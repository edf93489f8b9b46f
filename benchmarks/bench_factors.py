"""A measurement factor's callback: its state's pairs evaluated without re-checking them
(:meth:`~fgdoppler.models.observation.DopplerModel.at_state`) against the checked model path, on the graph of
an initiation window, alternately in one process."""

from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np
from numpy.typing import ArrayLike, NDArray

import fgdoppler as fd
from benchmarks._common import Row
from fgdoppler.graphs import chain_graph, chain_values
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
                ratio=ratio, target="<= 0.8x, identical", met=same and ratio <= 0.8)]


if __name__ == "__main__":
    for r in run():
        print(r)
