"""The mutation table per core module from the last `make mutate` (reads mutants/*.meta).

Run from the repository root after ``mutmut run``::

    python benchmarks/mutation_report.py            # the table
    python benchmarks/mutation_report.py --survivors semlab/control.py   # the surviving mutants' names

"Killed" counts mutants a test failed on, plus timeouts (a mutant that makes the tests hang is
caught); "no tests" are mutants in code no selected test calls (they count as not killed).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from collections import Counter
from pathlib import Path

import pandas as pd

# mutmut's exit codes: test failure (1, 3), timeout (36, 24, -24, 152, 255) and a crash of the test
# process (-11, -9: the mutant took the interpreter down) all mean the tests caught the mutant
KILLED = {1, 3, 36, 24, -24, 152, 255, -11, -9}
SURVIVED = {0}
NO_TESTS = {5, 33}


def load(root: Path = Path(".")) -> dict[str, dict[str, int | None]]:
    config = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["mutmut"]
    out = {}
    for module in config["only_mutate"]:
        for path in sorted(root.glob(module)):
            meta = root / "mutants" / f"{path.relative_to(root)}.meta"
            if meta.exists():  # (mutmut rewrites it while running: read it again if it was half written)
                for attempt in range(5):
                    try:
                        out[str(path.relative_to(root))] = json.loads(meta.read_text())["exit_code_by_key"]
                        break
                    except json.JSONDecodeError:
                        time.sleep(0.2 * (attempt + 1))
    return out


def table(results: dict[str, dict[str, int | None]]) -> pd.DataFrame:
    rows = []
    for module, codes in results.items():
        c = Counter("killed" if v in KILLED else "survived" if v in SURVIVED else "no tests" if v in NO_TESTS
                    else "not checked" if v is None else "other" for v in codes.values())
        checked = len(codes) - c["not checked"]
        rows.append({"module": module, "mutants": len(codes), "killed": c["killed"], "survived": c["survived"],
                     "no_tests": c["no tests"], "not_checked": c["not checked"], "other": c["other"],
                     "killed_pct": round(100.0 * c["killed"] / checked, 1) if checked else float("nan")})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--survivors", metavar="MODULE", help="list the surviving mutants of this module")
    parser.add_argument("--prefix", default="", help="only mutants whose name starts with this")
    parser.add_argument("--by-function", metavar="MODULE", help="the table per function of this module")
    args = parser.parse_args(argv)
    results = load()
    if not results:
        print("no mutation results: run `make mutate` first", file=sys.stderr)
        return 1
    if args.by_function:
        codes = results[args.by_function]
        per = {}
        for name, code in codes.items():
            per.setdefault(name.split(".", 2)[2].rsplit("__mutmut_", 1)[0], {})[name] = code
        print(table(per).rename(columns={"module": "function"}).to_string(index=False))
        return 0
    if args.survivors:
        for name, code in sorted(results[args.survivors].items()):
            if code in SURVIVED | NO_TESTS and name.startswith(args.prefix):
                print(name, "survived" if code in SURVIVED else "no tests")
        return 0
    print(table(results).to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
