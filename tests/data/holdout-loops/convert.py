#!/usr/bin/env python3
"""Rebuild the loop files of this folder from a checkout of github.com/greigpaterson/HystLab.

Usage: python3 convert.py PATH/TO/HystLab   (at commit 5d77ee01200ce467768d68c9be48bcba7c38949a)

Each source is a Princeton MicroMag VSM file: field mu0*H [T] and moment [A m^2], raw and as
"adjusted" by the instrument software (slope correction given in the header). The adjusted pair
(the last two columns of each data row) is kept. H = field / mu0 [A/m]. The sample volume is not
recorded ("Volume N/A"), so each loop's moment is scaled so that its largest |M| is M_NORMALISED:
M [A/m] is known up to that one factor, to which the J-A equations are invariant but the fit
not quite (the models' limit |alpha| < 1 and the search's M_s range: README.md).
"""
import math
import sys
from pathlib import Path

MU0 = 4e-7 * math.pi
M_NORMALISED_A_PER_M = 1e5
SOURCES = {
    "rock-a4-hystlab.csv": "Example_Data/Fig 10/A4.hys",
    "magnetosomes-conc40-c2a-hystlab.csv": "Example_Data/Fig 10/Conc_40_C2A.hys",
    "rock-h11-hystlab.csv": "Example_Data/Fig 10/H11.hys",
}


def rows(text):
    """Data rows: comma-separated numbers in the MicroMag form +d.ddddddE+dd (13 characters)."""
    for line in text.splitlines():
        cells = line.strip().split(",")
        if len(cells) < 4:
            continue
        try:
            values = [float(c) for c in cells]
        except ValueError:
            continue
        if cells[0].startswith(("+", "-")) and "E" in cells[0] and len(cells[0]) == 13:
            yield values


def main(root):
    here = Path(__file__).parent / "hystlab-bsd-3"
    for out, src in SOURCES.items():
        text = (Path(root) / src).read_text(encoding="latin-1")
        data = list(rows(text))
        scale = M_NORMALISED_A_PER_M / max(abs(v[-1]) for v in data)
        lines = ["field_A_per_m,magnetization_A_per_m"]
        for values in data:
            field_t, moment = values[-2], values[-1]
            lines.append(f"{field_t / MU0:.6g},{moment * scale:.6g}")
        (here / out).write_text("\n".join(lines) + "\n")
        print(out, len(data), "points")


if __name__ == "__main__":
    main(sys.argv[1])
