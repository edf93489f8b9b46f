"""Paper artefact: Figs. 10-11, position RMSE over Monte Carlo runs of the six scenarios with the CRLB
(see fgdoppler.analysis.reproduce.paper_monte_carlo).

Run: python studies/figs10_11_montecarlo.py [--out DIR]   (100 runs, about 2 minutes on 2 cores)
"""

from _common import out_dir

from fgdoppler.analysis.reproduce import ReproduceSettings, paper_monte_carlo

if __name__ == "__main__":
    out = out_dir("studies")
    _, (claims, lines, figs) = paper_monte_carlo(out, ReproduceSettings(runs=100, workers=2))
    print("\n".join(lines))
    for (name, claim), ok in claims.items():
        print(f"  [{'reproduced' if ok else 'NOT reproduced'}] {name}: {claim}")
    for f in figs:
        print(f"  wrote {f}")
