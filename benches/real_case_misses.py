"""The real cases' misses at a glance, for comparing a change to extraction: per case the targets it
misses and its log-excess (`realcases.CaseScore.log_excess`), and the totals, for the 14 cases and
the 10 held-out parts (tests/data/real_cases). Both cores, about 20 s; `benches/bench_extract.py`
prints every figure.

    python benches/real_case_misses.py [--held-out-only] [--only SUBSTRING]
"""

from __future__ import annotations

import argparse
import time
from multiprocessing import Pool
from pathlib import Path

from _table import print_table
from sketchrodgs import realcases

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "real_cases"


def score(job: tuple[str, int]) -> tuple[str, list[str], float]:
    """One case of the file `job[0]`, by index: its name, misses and log-excess."""
    scenes, cases = realcases.load_cases(DATA / job[0])
    case = cases[job[1]]
    s = realcases.score_case(case, realcases.run_case(scenes[case["scene"]], case, jitter=10))
    return case["name"], s.misses(), s.log_excess()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--held-out-only", action="store_true")
    parser.add_argument("--only", default="", help="cases whose name holds this")
    args = parser.parse_args()
    files = [("heldout_cases.json", "10 held-out parts")]
    if not args.held_out_only:
        files.insert(0, ("cases.json", "14 cases"))
    with Pool(2) as pool:
        for file, what in files:
            start = time.perf_counter()
            _, cases = realcases.load_cases(DATA / file)
            jobs = [(file, k) for k, case in enumerate(cases) if args.only in case["name"]]
            results = pool.map(score, jobs, chunksize=1)
            met = sum(not misses for _, misses, _ in results)
            total = sum(len(misses) for _, misses, _ in results)
            excess = sum(e for _, _, e in results if e < float("inf"))
            unmeasured = sum(e == float("inf") for _, _, e in results)
            print_table(
                f"{what}: {met} of {len(results)} meet every target, {total} misses, log-excess {excess:.2f}"
                + (f" and {unmeasured} not measurable" if unmeasured else "")
                + f" ({time.perf_counter() - start:.0f} s)",
                ["case", "log-excess", "misses"],
                [[name, f"{e:.2f}", "; ".join(misses) or "none"] for name, misses, e in results],
            )


if __name__ == "__main__":
    main()
