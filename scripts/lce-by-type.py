#!/usr/bin/env python3
"""LCE-Unmixed error by curve type and number of instances, from `multifit-train eval --json`.

    ./target/release/multifit-train eval --model models/lce --data runs/data/lce-unmixed-test \
        --k-max 6 --json > runs/lce-unmixed-eval.json
    python3 scripts/lce-by-type.py runs/lce-unmixed-eval.json runs/data/lce-unmixed-test

Prints a Markdown table: mean error with known K in % (samples) per type and K. The type of a
sample is read from the `source` line `multifit-train gen-lce` writes into each sample file.
"""

import json
import re
import sys
from collections import defaultdict
from pathlib import Path


def main() -> None:
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    rows = json.loads(Path(sys.argv[1]).read_text())["rows"]
    data = Path(sys.argv[2])
    cells: dict[tuple[str, int], list[float]] = defaultdict(list)
    for row in rows:
        source = json.loads((data / f"{row['name']}.json").read_text())["source"]
        match = re.search(r"shapes \[(\w+)", source)
        if not match:
            raise SystemExit(f"{row['name']}: no shape list in source {source!r}")
        cells[(match.group(1).lower(), row["k_true"])].append(row["known"]["error"])
    ks = sorted({k for _, k in cells})
    print("| type | " + " | ".join(f"K = {k}" for k in ks) + " |")
    print("|---|" + "---|" * len(ks))
    for shape in ("line", "circle", "ellipse"):
        out = []
        for k in ks:
            e = cells.get((shape, k), [])
            out.append(f"{100 * sum(e) / len(e):.2f} ({len(e)})" if e else "-")
        print(f"| {shape}s | " + " | ".join(out) + " |")


if __name__ == "__main__":
    main()
