"""Builders never crash on a seed: per builder, the share of seeds whose pure layout builds with its invariants.

For each builder (tests/layout_cases.py: street, parking, industrial_hall, railway, primitives) and each seed
0 .. N - 1, the seed draws random valid parameters and sensor poses and the builder's pure layout (no Blender) is
built: a seed *builds* when it raises nothing and keeps the invariants (no intersecting solids, no solid within
0.5 m of any sensor pose), or is *refused* in one line by the builder's check. Must read 100 % for every builder.
One more row per junction kind (cross, t_junction, straight) builds the street with every other key at its default
over layout seeds 0 .. M - 1 (the issue's 200 layouts, of which seeds 13 and 188 crashed).

Run: python benchmarks/bench_layout_seeds.py [--small]   (1,000 seeds a builder; --small: 100)
"""

from __future__ import annotations

import os
import sys
import time
import traceback

import numpy as np

from common import ROOT, arguments, report

sys.path.insert(0, str(ROOT / "tests"))
import layout_cases


def builder_row(name: str, seeds: int) -> dict:
    """One builder over ``seeds`` seeds: how many built, were refused, crashed or broke an invariant."""
    case = layout_cases.CASES[name]
    built = refused = crashed = broken = 0
    first = None
    start = time.perf_counter()
    for seed in range(seeds):
        try:
            lines = case(seed)
        except Exception:
            crashed += 1
            first = first or f"seed {seed}: {traceback.format_exc(limit=1).splitlines()[-1]}"
            continue
        if lines is None:
            refused += 1
        elif lines:
            broken += 1
            first = first or f"seed {seed}: {lines[0]}"
        else:
            built += 1
    seconds = time.perf_counter() - start
    return {"builder": name, "seeds": seeds, "built": built, "refused_in_one_line": refused, "crashed": crashed, "broke_an_invariant": broken,
            "share_that_build_%": round(100.0 * (built + refused) / seeds, 2), "ms_per_seed": round(1000 * seconds / seeds, 1), "first_failure": first}


def default_street_row(seeds: int, kind: str) -> dict:
    """The street of junction ``kind``, every other key at its default, over layout seeds 0 .. seeds - 1."""
    from bpy_pipeline.builders.street.layout import street_layout
    from bpy_pipeline.builders.street.params import StreetScene

    crashed, first = 0, None
    start = time.perf_counter()
    for seed in range(seeds):
        try:
            street_layout(StreetScene(layout_seed=seed, junction_mix={kind: 1.0}), np.random.default_rng(seed))
        except Exception:
            crashed += 1
            first = first or f"seed {seed}: {traceback.format_exc(limit=1).splitlines()[-1]}"
    seconds = time.perf_counter() - start
    return {"builder": f"street (defaults, {kind})", "seeds": seeds, "built": seeds - crashed, "refused_in_one_line": 0, "crashed": crashed,
            "broke_an_invariant": 0,
            "share_that_build_%": round(100.0 * (seeds - crashed) / seeds, 2), "ms_per_seed": round(1000 * seconds / seeds, 1), "first_failure": first}


def main():
    args = arguments(__doc__)
    seeds, defaults = (100, 20) if args.small else (1000, 200)
    load = os.getloadavg()[0]
    from bpy_pipeline.builders.street.layout import JUNCTIONS

    rows = [builder_row(name, seeds) for name in layout_cases.CASES] + [default_street_row(defaults, kind) for kind in JUNCTIONS]
    report("layout_seeds" + ("_small" if args.small else ""), rows, args.out,
           {"command": "python benchmarks/bench_layout_seeds.py" + (" --small" if args.small else ""), "load_average_before": round(load, 2),
            "builds": "no exception, and the invariants of tests/layout_cases.py hold, or the builder's check refuses the drawn parameters in one line"})
    failing = [row["builder"] for row in rows if row["share_that_build_%"] < 100.0]
    if failing:
        sys.exit(f"bench_layout_seeds: not every seed builds for {', '.join(failing)}")


if __name__ == "__main__":
    main()
