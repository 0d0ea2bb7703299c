"""Execute a notebook (CI: scripts/python_test.sh) with the current Python's
kernel, in the repository's root (the notebook reads data/example/). Fails
on the first cell that raises. Usage: run_notebook.py NOTEBOOK.ipynb"""

import sys
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

path = Path(sys.argv[1]).resolve()
root = Path(__file__).resolve().parents[2]
nb = nbformat.read(path, as_version=4)
t0 = time.time()
NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(root)}}).execute()
print(f"{path.name}: {len(nb.cells)} cells executed in {time.time() - t0:.1f} s")
