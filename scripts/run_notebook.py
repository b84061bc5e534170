"""Executes a notebook with nbclient (as CI does: scripts/check_python.sh) in its own folder,
without writing it back; a cell that raises fails with the cell and its error.

Usage: .venv/bin/python scripts/run_notebook.py NOTEBOOK.ipynb [--timeout S]
"""

import argparse
import sys
from pathlib import Path

import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("notebook", type=Path)
    ap.add_argument("--timeout", type=int, default=600, help="per cell, s")
    a = ap.parse_args()
    nb = nbformat.read(a.notebook, as_version=4)
    client = NotebookClient(
        nb,
        timeout=a.timeout,
        kernel_name="python3",
        resources={"metadata": {"path": str(a.notebook.parent)}},
    )
    try:
        client.execute()
    except CellExecutionError as e:
        print(f"{a.notebook}: a cell failed:\n{e}", file=sys.stderr)
        return 1
    cells = sum(1 for c in nb.cells if c.cell_type == "code")
    print(f"{a.notebook}: {cells} code cells executed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
