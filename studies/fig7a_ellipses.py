"""Paper artefact: fig7a ellipses (see fgdoppler.analysis.artefacts.fig7a_ellipses).

Run: python studies/fig7a_ellipses.py [--out DIR]
"""

from _common import out_dir, report

from fgdoppler.analysis.artefacts import fig7a_ellipses

if __name__ == "__main__":
    out = out_dir("studies")
    report(fig7a_ellipses(out))
