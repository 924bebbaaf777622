"""Compare the result tables of two runs of the same studies, cell by cell.

Usage: ``python scripts/compare_tables.py BEFORE_DIR AFTER_DIR [--new-columns a,b]``

Every ``*.csv`` and ``summary.json`` under BEFORE_DIR is compared with the file of the same
path under AFTER_DIR: byte for byte, or else as text cells on the columns BEFORE had
(columns named by ``--new-columns`` may be added; ``worker_peak_rss_MiB`` is a measurement
of the machine and differs between any two runs). Exit code 0 when every table agrees.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import pandas as pd

MACHINE_COLUMNS = {"worker_peak_rss_MiB"}


def compare(before: Path, after: Path, new_columns: set[str]) -> bool:
    """Print one line per table; True when all agree."""
    ok = True
    for b in sorted([*before.rglob("*.csv"), *before.rglob("summary.json")]):
        rel = b.relative_to(before)
        if "tasks" in rel.parts:
            continue
        a = after / rel
        if not a.exists():
            print(f"{rel}: MISSING")
            ok = False
        elif a.read_bytes() == b.read_bytes():
            print(f"{rel}: byte-identical")
        elif b.suffix != ".csv":
            print(f"{rel}: DIFFERENT")
            ok = False
        else:
            old = pd.read_csv(b, dtype=str, keep_default_na=False)
            new = pd.read_csv(a, dtype=str, keep_default_na=False)
            added = [c for c in new.columns if c not in old.columns]
            unexpected = [c for c in added if c not in new_columns]
            keep = [c for c in old.columns if c not in MACHINE_COLUMNS]
            same = not unexpected and set(old.columns) <= set(new.columns) and old[keep].equals(new[keep])
            print(f"{rel}: {'identical' if same else 'DIFFERENT'} on its {len(keep)} columns; added {added}")
            ok &= same
    return ok


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before", type=Path)
    parser.add_argument("after", type=Path)
    parser.add_argument("--new-columns", default="", help="Comma-separated columns the after-run may add.")
    args = parser.parse_args()
    sys.exit(0 if compare(args.before, args.after, set(filter(None, args.new_columns.split(",")))) else 1)


if __name__ == "__main__":
    main()
