#!/usr/bin/env python3
"""Rebuilds the loop files of this folder (and of ../jamodel-simulated) from the two source
repositories (see README.md).

Usage: convert.py JAMODEL_CHECKOUT JAFIT_CHECKOUT   (needs numpy and scipy for the .mat files)

Every file is written in the workbench's loop format (docs/formats.md): a header
`field_A_per_m,flux_density_T`, then the points in the source's order. Values are the source's,
unscaled (both sources give H in A/m and B in T); only the largest-amplitude loop of each
multi-loop .mat file is kept.
"""
import os
import sys

import scipy.io

JAMODEL = {
    # output name: (folder, stem of H_*.mat / B_*.mat)
    "jamodel-mit/steel-m130-27s-jamodel.csv": ("3_mixed/Characterisitcs_mixed_mat", "M130_27s"),
    "jamodel-mit/ferrite-mnzn-jamodel.csv": ("1_isotropic/Characterisitcs_isotropic_mat", "MnZn_ferrite"),
    "jamodel-mit/ferrite-mnzn-hp-jamodel.csv": ("11_TwoStepSolver/Characteristics_isotropic_mat", "MnZn_HP_ferrite"),
    "jamodel-mit/ferrite-mnzn-a2018-jamodel.csv": ("12_Automation2018/Characterisitcs_isotropic_mat", "MnZn_ferrite"),
    "jamodel-mit/amorphous-alloy-jamodel.csv": ("2_anisotropic/Characterisitcs_anisotropic_mat", "amorf"),
}
# The JAmodel code's OWN SIMULATION (BsimT4) of the major loop at its published coefficient set:
# the reference our `szewczyk` variant is checked against (not a measurement).
SIMULATED = {
    "../jamodel-simulated/ferrite-mnzn-a2018-simulated-by-jamodel.csv": "12_Automation2018/ResultsJA.mat",
    "../jamodel-simulated/ferrite-mnzn-hp-simulated-by-jamodel.csv": "11_TwoStepSolver/Results.mat",
}
JAFIT = {
    "jafit-gpl-3.0/soft-steel-altair-jafit.csv": "data/B(H).Altair_Flux.Example.csv",
    "jafit-gpl-3.0/alnico5-campbell-jafit.csv": "data/B(H).Campbell.AlNiCo_5.tab",
    "jafit-gpl-3.0/alnico-jesenik-jafit.csv": "data/B(H).Jesenik.AlNiCo.tab",
}


def write(name, pairs):
    with open(os.path.join(os.path.dirname(__file__), name), "w") as f:
        f.write("field_A_per_m,flux_density_T\n")
        for h, b in pairs:
            f.write(f"{h:.10g},{b:.10g}\n")


def main(jamodel, jafit):
    for name, (folder, stem) in JAMODEL.items():
        h = scipy.io.loadmat(os.path.join(jamodel, folder, f"H_{stem}.mat"))["HmeasT"]
        b = scipy.io.loadmat(os.path.join(jamodel, folder, f"B_{stem}.mat"))["BmeasT"]
        col = abs(h).max(axis=0).argmax()  # the major (largest-amplitude) loop
        write(name, zip(h[:, col], b[:, col]))
    for name, path in SIMULATED.items():
        d = scipy.io.loadmat(os.path.join(jamodel, path))
        col = abs(d["HmeasT"]).max(axis=0).argmax()
        write(name, zip(d["HmeasT"][:, col], d["BsimT4"][:, col]))
    for name, path in JAFIT.items():
        rows = []
        with open(os.path.join(jafit, path)) as f:
            for line in f:
                cells = line.replace(",", "\t").split()
                try:
                    rows.append((float(cells[0]), float(cells[1])))
                except (ValueError, IndexError):
                    continue  # the header
        write(name, rows)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
