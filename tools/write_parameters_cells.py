"""Write each book notebook's ``parameters`` cell (notebooks/src/NN_<name>.py) from its settings dataclass.

usage: python tools/write_parameters_cells.py [--check]   (``make notebooks`` runs it before jupytext)
The cell keeps the names the runner injects and lists every setting with its paper value from
fnnbook.tasks.<name> (fnnbook.params.parameters_cell). With --check, writes nothing and exits 1 when a cell
differs from its dataclass.
"""
import re
import sys
from pathlib import Path

from fnnbook.params import parameters_cell
from fnnbook.tasks import NOTEBOOKS

SRC = Path(__file__).resolve().parents[1] / "notebooks" / "src"
CELL = re.compile(r'(^# %% tags=\["parameters"\]\n)(.*?)(\n*)(?=^# %%)', re.MULTILINE | re.DOTALL)


def main(check: bool) -> int:
    stale = []
    for path in sorted(SRC.glob("*.py")):
        name = re.sub(r"^\d+_", "", path.stem)
        if name not in NOTEBOOKS:
            continue
        text = path.read_text(encoding="utf-8")
        found = CELL.search(text)
        if found is None:
            sys.exit(f"{path.name}: no parameters cell")
        cell = parameters_cell(name, found.group(2))
        new = text[:found.start(2)] + cell + "\n" + text[found.end(3):]
        if new != text:
            stale.append(path.name)
            if not check:
                path.write_text(new, encoding="utf-8")
    if stale:
        print(("parameters cells differ from their settings: " if check else "wrote: ") + ", ".join(stale))
    return 1 if check and stale else 0


if __name__ == "__main__":
    sys.exit(main("--check" in sys.argv[1:]))
