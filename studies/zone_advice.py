r"""Does following the smoother's zone advice lead to the truth, or to a confident mirror track?

A quasi-monostatic radar (transmitter and receiver 20 m apart) and a
bistatic receiver 30 km away: three sensors within 3.3 m of one line, so a
track and its mirror image across that line give nearly the same Doppler.
The target starts 9.4 km off the line, outside the default zone (a strip
about ±3 km wide).  Per seed:

1. ``fgdoppler track`` with the smoother and the default zone: the verdict,
   and the ``--zone ... --speed-max ...`` it advises;
2. the same with the advised options: the verdict, the final position's
   distance from the truth and its squared Mahalanobis distance, and
   whether a ``competing`` finding says another track fits as well.

Both with the advice as the library gives it (the start found outside the
zone and, where it is a mode the data cannot tell from it, its mirror
image's twin) and without the twin (``--no-twin``: the mirror image is
replaced by the start itself, so only the start found is advised) — the
rule measured before the twin was added.

Run: python studies/zone_advice.py [--seeds 8] [--no-twin 1] [--out DIR]   (about 15 s on 2 cores)
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from _common import each_count

from fgdoppler.cli import main as cli

#: The layout (a file, shared with the test of the advice in ``tests/test_cli.py``).
GEOMETRY = Path(__file__).resolve().parent / "geometries" / "quasi_monostatic.toml"
#: The target: start (m), velocity (m/s).
START = ("15000", "12000")
VELOCITY = ("80", "-60")
ADVICE = re.compile(r"e\.g\. (--zone -?\d+ -?\d+ -?\d+ -?\d+(?: --altitude -?\d+ -?\d+)? --speed-max \d+)")


def _quiet(args: list[str]) -> int:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return cli(args)


def one(seed: int, no_twin: float = 0.0) -> dict[str, Any]:
    """Both runs of one seed (rule: module docstring)."""
    if no_twin:
        import fgdoppler.estimators.smoother_offsets as offsets

        # the twin search starts from the mirror image; from the start itself it finds the start's own mode,
        # never a twin, so only the start found is advised
        offsets.mirrored = lambda states, geometry: np.asarray(states, dtype=float)
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        _quiet(["simulate", "--geometry", str(GEOMETRY), "--start-x", START[0], "--start-y", START[1],
                "--velocity", *VELOCITY, "--seed", str(seed), "--out", str(d / "sim")])
        truth = np.loadtxt(d / "sim" / "truth.csv", delimiter=",", skiprows=1)[-1, 1:3]
        row: dict[str, Any] = {"seed": seed}
        extra: list[str] = []
        for step in ("default zone", "advised zone"):
            _quiet(["track", str(d / "sim" / "measurements.csv"), "--estimator", "smoother",
                    "--out", str(d / "t.csv"), *extra])
            res = json.loads((d / "t.json").read_text())
            x, P = np.array(res["states"][-1]), np.array(res["covariances"][-1])
            e = x[:2] - truth
            advice = [m for r in res["reasons"] if r["status"] != "ok" and (m := ADVICE.search(r["message"]))]
            row[step] = {"status": res["status"], "error": float(np.linalg.norm(e)),
                         "mahalanobis2": float(e @ np.linalg.solve(P[:2, :2], e)),
                         "competing": any(r["code"] == "competing" and r["status"] != "ok" for r in res["reasons"]),
                         "advice": advice[0].group(1) if advice else ""}
            if not advice:
                break
            extra = advice[0].group(1).split()
        return row


def main() -> None:
    args, rows = each_count(one, __doc__.splitlines()[0], "seeds", 8, {"no_twin": 0.0})
    lines = [f"advice {'without' if args.no_twin else 'with'} the mirror twin; {args.seeds} seeds", "",
             "| seed | default zone | advised | advised zone: status, error (m), squared Mahalanobis, competing |",
             "|---|---|---|---|"]
    for r in rows:
        a = r.get("advised zone")
        after = "" if a is None else \
            f"{a['status']}, {a['error']:,.0f}, {a['mahalanobis2']:,.1f}, {'yes' if a['competing'] else 'no'}"
        lines.append(f"| {r['seed']} | {r['default zone']['status']}, {r['default zone']['error']:,.0f} m | "
                     f"`{r['default zone']['advice']}` | {after} |")
    text = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"zone_advice{'_no_twin' if args.no_twin else ''}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
