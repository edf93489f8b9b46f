"""Paper artefact: fig3 geometry (see fgdoppler.analysis.artefacts.fig3_geometry).

Run: python studies/fig3_geometry.py [--out DIR]
"""

from _common import out_dir, report

from fgdoppler.analysis.artefacts import fig3_geometry

if __name__ == "__main__":
    out = out_dir("studies")
    report(fig3_geometry(out))
