"""Distances in messages (fgdoppler._text.distance_text): read back to the precision they are printed with."""

from __future__ import annotations

import re

import numpy as np
import pytest

import fgdoppler as fd
from fgdoppler._text import distance_text


@pytest.mark.parametrize("d", [0.0, 0.004, 0.43, 4.24, 9.96, 10.0, 37.1, 437.4, 999.4, 1000.0, 1049.0, 23012.0,
                               4.5e6, -5000.0, -37.1, -0.43])
def test_a_distance_reads_back_to_its_printed_precision_and_never_as_zero_km(d: float) -> None:
    text = distance_text(d)
    value, unit = re.fullmatch(r"(-?[0-9.]+(?:e-?[0-9]+)?) (m|km)", text).groups()  # type: ignore[union-attr]
    metres = float(value) * (1e3 if unit == "km" else 1.0)
    if abs(d) >= 1e3:
        assert unit == "km" and abs(metres - d) <= 50.0  # 0.1 km
    elif abs(d) >= 10.0 or d == 0.0:
        assert unit == "m" and abs(metres - d) <= 0.5 and "." not in value
    else:
        assert unit == "m" and abs(metres - d) <= 0.05 * abs(d)  # two significant digits
    assert np.sign(metres) == np.sign(d)
    assert float(distance_text(d, km_decimals=2).split()[0]) * (1e3 if abs(d) >= 1e3 else 1.0) == \
        pytest.approx(d, abs=5.0 if abs(d) >= 1e3 else 0.5 if abs(d) >= 10.0 else 0.05 * abs(d))


def test_a_small_layouts_findings_give_metres_not_zero_km() -> None:
    """The paper's case b pairs with their positions given in kilometres where metres are read (a target
    simulated 25 km out, so the data fit nothing near sensors 50 m apart): the initiation's boundary finding
    said "0.0 km away"; the distance it gives now is the one LM found, in metres."""
    g_m = fd.paper_geometry("b")
    sim = fd.simulate(fd.paper_scenario("b", 25e3), np.random.default_rng(3))
    g_km = fd.Geometry(pairs=tuple(fd.BistaticPair(tx=np.array(p.tx) / 1e3, rx=np.array(p.rx) / 1e3)
                                   for p in g_m.pairs))
    init = fd.initiate(sim.measurements.first_per_pair(10), g_km)
    text = " ".join(r.message for r in init.reasons)
    assert "0.0 km" not in text
    found = re.search(r"without the bound LM reaches window cost [0-9.]+ ([0-9.]+) (m|km) away", text)
    assert found is not None and found.group(2) == "m" and float(found.group(1)) > 0.0, text
