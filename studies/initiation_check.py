"""Initiation study (issue: track initiation): chi-square pass rate, RMSE vs window CRLB, time.

Run: python studies/initiation_check.py [--out DIR]   (100 runs x 6 scenarios, about 1-2 minutes)
"""

import json

from _common import out_dir

from fgdoppler.analysis.initiation_study import initiation_study

if __name__ == "__main__":
    out = out_dir("studies")
    rows = initiation_study(runs=100)
    print(f"{'scenario':22s} {'pass':>5s} {'amb':>4s} {'RMSE end':>9s} {'CRLB':>7s} {'ratio':>6s} {'median s':>9s} {'p90 s':>7s}")
    for r in rows:
        print(f"{r.scenario:22s} {r.passes_chi2:5d} {r.ambiguous:4d} {r.pos_rmse_end:9.0f} {r.crlb_pos_end:7.0f} "
              f"{r.pos_rmse_end / r.crlb_pos_end:6.2f} {r.median_time:9.3f} {r.p90_time:7.3f}")
    out.mkdir(parents=True, exist_ok=True)
    (out / "initiation_check.json").write_text(json.dumps([r.to_dict() for r in rows], indent=1))
