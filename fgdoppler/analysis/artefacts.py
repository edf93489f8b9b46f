"""The paper's observability artefacts (Figs. 3–8, Table 2) as functions writing into a folder.

Each function computes its artefact with the library, writes a figure (and a
JSON/Markdown file where there are numbers) into ``out`` and returns what it
computed, so ``studies/`` scripts and ``fgdoppler reproduce`` share one code path.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fgdoppler import plotting
from fgdoppler._io import atomic_write_text
from fgdoppler.analysis.observability import (
    DEFAULT_X,
    PAPER_GROUPS,
    TABLE2_SAMPLING,
    ObservabilityMap,
    SamplingPattern,
    SpeedTable,
    observability_map,
    speed_table,
)
from fgdoppler.geometry import paper_geometry

__all__ = ["Artefact", "fig3_geometry", "fig7a_ellipses", "fig8_slices", "figs4_7_maps", "table2"]


@dataclass(frozen=True, kw_only=True)
class Artefact:
    """What an artefact function produced: files, a short summary, and claims checked."""

    name: str
    files: tuple[Path, ...]
    summary: str
    #: claim text -> reproduced?
    claims: dict[str, bool] = field(default_factory=dict)


def fig3_geometry(out: Path) -> Artefact:
    """Figs. 1/3: the two configurations with baselines and the evaluation groups."""
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    _, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    for ax, (case, groups) in zip(axes, (("a", (1, 2)), ("b", (3, 4))), strict=True):
        pts = {f"group {g}": np.stack([DEFAULT_X, np.full_like(DEFAULT_X, PAPER_GROUPS[g][1])], 1)[::8]
               for g in groups}
        plotting.plot_geometry(paper_geometry(case), ax, groups=pts)
        ax.set_title(f"case ({case})")
    path = plotting.save(axes[0], out / "fig3_geometry.png")
    return Artefact(name="Fig. 3", files=(path,), summary="sensor configurations and evaluation groups")


def figs4_7_maps(out: Path, *, speed: float = 100.0, sampling: SamplingPattern = TABLE2_SAMPLING) -> tuple[Artefact, dict[int, ObservabilityMap]]:
    """Figs. 4–7: O over x × heading for groups 1–4, and the paper's baseline claim."""
    out.mkdir(parents=True, exist_ok=True)
    maps: dict[int, ObservabilityMap] = {}
    files = []
    for g, (case, y) in PAPER_GROUPS.items():
        m = observability_map(paper_geometry(case), y=y, speed=speed, sampling=sampling)
        maps[g] = m
        ax = plotting.plot_observability_map(m, title=f"group {g}: case ({case}), y = {y / 1e3:g} km")
        files.append(plotting.save(ax, out / f"fig{g + 3}_map_group{g}.png"))
    claims = {}
    for g in (1, 3):
        m = maps[g]
        along = np.isin(m.heading_deg, (90.0, 270.0))
        claims[f"group {g}: headings 90/270 deg unobservable (O = -40), others observable"] = bool(
            np.all(m.O[:, along] <= -40) and np.all(m.O[:, ~along] > -40)
        )
    for g in (2, 4):
        claims[f"group {g}: all O > -40"] = bool(np.all(maps[g].O > -40))
    summ = "; ".join(f"group {g}: O in [{m.O.min():.2f}, {m.O.max():.2f}]" for g, m in maps.items())
    return Artefact(name="Figs. 4-7", files=tuple(files), summary=summ, claims=claims), maps


def fig7a_ellipses(out: Path) -> Artefact:
    """Fig. 7a: bistatic ellipses through a point at mid-baseline and at a branch."""
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    _, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    for ax, x in zip(axes, (25e3, 5e3), strict=True):
        plotting.plot_geometry(paper_geometry("a"), ax, ellipse_through=(x, 2e3))
        ax.set_title(f"case (a), point ({x / 1e3:g} km, 2 km)")
        ax.set_aspect("auto")
        ax.set_ylim(-4, 5)
    path = plotting.save(axes[0], out / "fig7a_ellipses.png")
    return Artefact(name="Fig. 7a", files=(path,), summary="bistatic ellipses through (25, 2) km and (5, 2) km")


def fig8_slices(out: Path, *, heading_deg: float = 180.0, sampling: SamplingPattern = TABLE2_SAMPLING) -> Artefact:
    """Fig. 8: O vs x at heading 180° for groups 2 and 4, and the paper's claims about it."""
    out.mkdir(parents=True, exist_ok=True)
    curves = {}
    for g in (2, 4):
        case, y = PAPER_GROUPS[g]
        m = observability_map(paper_geometry(case), y=y, heading_deg=[heading_deg], sampling=sampling)
        curves[f"group {g}"] = (m.x, m.O[:, 0])
    path = plotting.save(plotting.plot_observability_slice(curves, heading_deg=heading_deg), out / "fig8_slices.png")
    x, O2 = curves["group 2"]
    _, O4 = curves["group 4"]
    mid = (x > 15e3) & (x < 35e3)
    claims = {
        "O is lower near the middle of x than at the ends (groups 2 and 4)": bool(
            O2[mid].mean() < min(O2[x < 5e3].mean(), O2[x > 45e3].mean())
            and O4[mid].mean() < min(O4[x < 5e3].mean(), O4[x > 45e3].mean())
        ),
        "group 2 is best near x = 50 km, group 4 near x = 0": bool(
            O2[x > 45e3].mean() > O2[x < 5e3].mean() and O4[x < 5e3].mean() > O4[x > 45e3].mean()
        ),
    }
    atomic_write_text(out / "fig8_slices.json", json.dumps(
        {k: {"x": v[0].tolist(), "O": v[1].tolist()} for k, v in curves.items()}))
    return Artefact(name="Fig. 8", files=(path, out / "fig8_slices.json"),
                    summary=f"heading {heading_deg:g} deg", claims=claims)


def table2(out: Path, *, sampling: SamplingPattern = TABLE2_SAMPLING) -> tuple[Artefact, SpeedTable]:
    """Table 2: max/min O per speed for groups 2 and 4, beside the paper's values."""
    out.mkdir(parents=True, exist_ok=True)
    tab = speed_table(sampling=sampling)
    md = tab.to_markdown()
    atomic_write_text(out / "table2.md", md + "\n")
    atomic_write_text(out / "table2.json", json.dumps({"sampling": sampling.describe(), "rows": tab.compare()}, indent=1))
    rows = tab.compare()
    max_ok = all(abs(r["max"] - r["paper_max"]) <= 0.05 for r in rows)
    min_ok = all(abs(r["min"] - r["paper_min"]) <= 1.0 for r in rows)
    incr = all(
        all(tab.values[g][a][0] > tab.values[g][b][0] for a, b in zip(tab.speeds, tab.speeds[1:], strict=False))
        for g in tab.groups
    )
    claims = {
        "max column within 0.05 of the paper": max_ok,
        "min column within 1.0 of the paper": min_ok,
        "observability increases with speed": incr,
    }
    return Artefact(name="Table 2", files=(out / "table2.md", out / "table2.json"), summary=md, claims=claims), tab
