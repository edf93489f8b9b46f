"""Paper artefact: figs4 7 maps (see fgdoppler.analysis.artefacts.figs4_7_maps).

Run: python studies/figs4_7_maps.py [--out DIR]
"""

from _common import out_dir, report

from fgdoppler.analysis.artefacts import figs4_7_maps

if __name__ == "__main__":
    out = out_dir("studies")
    report(figs4_7_maps(out)[0])
