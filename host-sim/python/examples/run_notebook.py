"""Runs a notebook's code cells in order, in one namespace, without Jupyter: the test command's
check that the example notebook's steps work. Plots go to a non-interactive backend.

Usage: python run_notebook.py NOTEBOOK.ipynb   (the cells run in the notebook's folder)
"""

import json
import os
import sys
import time
import traceback
from pathlib import Path


def main(path: str) -> int:
    nb_path = Path(path).resolve()
    cells = json.loads(nb_path.read_text(encoding="utf-8"))["cells"]
    os.environ.setdefault("MPLBACKEND", "Agg")  # plt.show() returns at once, no display needed
    os.chdir(nb_path.parent)
    namespace = {"__name__": "__main__"}
    code_cells = [c for c in cells if c["cell_type"] == "code"]
    for k, cell in enumerate(code_cells, 1):
        source = "".join(cell["source"])
        start = time.monotonic()
        print(f"--- cell {k}/{len(code_cells)}", flush=True)
        try:
            exec(compile(source, f"{nb_path.name}, code cell {k}", "exec"), namespace)
        except Exception:
            traceback.print_exc()
            print(f"FAIL: {nb_path.name}: code cell {k} raised", file=sys.stderr)
            return 1
        print(f"    ({time.monotonic() - start:.1f} s)", flush=True)
    print(f"ok: {nb_path.name}: {len(code_cells)} code cells ran")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1]))
