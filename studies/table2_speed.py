"""Paper artefact: table2 speed (see fgdoppler.analysis.artefacts.table2).

Run: python studies/table2_speed.py [--out DIR]
"""

from _common import out_dir, report

from fgdoppler.analysis.artefacts import table2

if __name__ == "__main__":
    out = out_dir("studies")
    report(table2(out)[0])
