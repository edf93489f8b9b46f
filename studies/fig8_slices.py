"""Paper artefact: fig8 slices (see fgdoppler.analysis.artefacts.fig8_slices).

Run: python studies/fig8_slices.py [--out DIR]
"""

from _common import out_dir, report

from fgdoppler.analysis.artefacts import fig8_slices

if __name__ == "__main__":
    out = out_dir("studies")
    report(fig8_slices(out))
