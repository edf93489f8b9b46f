"""New study: position RMSE of the fixed-lag smoother versus lag, with the EKF and the full smoother
(see fgdoppler.analysis.reproduce.lag_sweep).

Run: python studies/lag_sweep.py [--out DIR]
"""

from _common import out_dir

from fgdoppler.analysis.reproduce import ReproduceSettings, lag_sweep

if __name__ == "__main__":
    out = out_dir("studies")
    lines, fig = lag_sweep(out, ReproduceSettings(runs=100, workers=2))
    print("\n".join(lines))
    print(f"  wrote {fig}")
