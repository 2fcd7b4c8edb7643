#!/usr/bin/env python3
"""Traces the rays `vtfarm bench rays --dump-rays DIR` wrote with Embree
(the `embreex` package: `pip install embreex numpy`), one rtcIntersect1 call
per ray on one thread, and prints closest-hit rays per second per set, best of
--rounds passes (only the queries are timed; the BVH build is printed apart),
per second of wall-clock and of this process's CPU time (the fair figure on
a busy machine; `bench rays` reports both).

embreex offers Embree's single-ray API only (no rtcIntersect4/8/16 or stream
calls), so these are single-ray figures.

Also checks that Embree found the same hits as vtfarm: the share of rays whose
hit/miss agrees and, among hits in both, whose t agrees to 1e-4 relative
(watertight tests differ on edges and the scenes have coplanar overlaps, so a
few in a million may differ).

With --vtfarm-json FILE (the `--json` of a `bench rays` run on the same rays)
it prints vtfarm/Embree ratios. For a fair ratio on a busy machine alternate
the two runs (see docs/benchmarks.md, "Ray throughput").

    scripts/embree_rays.py DIR [--rounds 3] [--vtfarm-json FILE] [--json OUT]
"""

import argparse
import json
import os
import sys
import time

import numpy as np

try:
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh
except ImportError:
    sys.exit("embree_rays.py needs embreex: pip install embreex numpy")

SETS = ("primary", "incoherent", "reflection")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dir", help="the --dump-rays directory")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--vtfarm-json", help="figures of a `bench rays --json` run")
    parser.add_argument("--json", help="also write Embree's figures here")
    args = parser.parse_args()

    def load(name):
        return np.load(os.path.join(args.dir, name + ".npy"))

    triangles = load("triangles").astype(np.float32)
    start = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, triangles)
    # The build happens on the first query (commit): trace one ray for it.
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))
    build = time.perf_counter() - start
    print(f"{len(triangles)} triangles, Embree build {build:.3f} s, best of {args.rounds}")

    figures = {"triangles": len(triangles), "bvh_build_seconds": build}
    vtfarm = json.load(open(args.vtfarm_json)) if args.vtfarm_json else None
    for name in SETS:
        origins = np.ascontiguousarray(load(name + "_origins"), np.float32)
        directions = np.ascontiguousarray(load(name + "_directions"), np.float32)
        best_wall = best_cpu = float("inf")
        for _ in range(args.rounds):
            start, cpu_start = time.perf_counter(), time.process_time()
            result = scene.run(origins, directions, output=1)
            best_wall = min(best_wall, time.perf_counter() - start)
            best_cpu = min(best_cpu, time.process_time() - cpu_start)
        print(f"{name:<11} {len(origins):>9} rays  " + agreement(result, load(name + "_hits")))
        for suffix, best, unit in (
            ("_rays_per_second", best_wall, "rays/s"),
            ("_rays_per_cpu_second", best_cpu, "rays/CPU-s"),
        ):
            rate = len(origins) / max(best, 1e-9) if len(origins) else 0.0
            figures[name + suffix] = rate
            line = f"    Embree {rate / 1e6:7.2f} M {unit:<10}"
            if vtfarm is not None and name + suffix in vtfarm:
                ours = vtfarm[name + suffix]
                line += f"  vtfarm {ours / 1e6:7.2f} M  vtfarm/Embree {ours / max(rate, 1e-9):.2f}"
            print(line)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f, indent=2)


def agreement(result, vtfarm_t):
    """How many of Embree's hits match the t vtfarm recorded per ray."""
    # embreex reports a miss as geomID -1 (RTC_INVALID_GEOMETRY_ID as int32).
    embree_hit = result["geomID"].astype(np.int64) >= 0
    embree_t = np.where(embree_hit, result["tfar"], np.inf)
    vtfarm_hit = np.isfinite(vtfarm_t)
    same_outcome = embree_hit == vtfarm_hit
    both = embree_hit & vtfarm_hit
    close = np.abs(embree_t[both] - vtfarm_t[both]) <= 1e-4 * np.maximum(1.0, vtfarm_t[both])
    count = max(len(vtfarm_t), 1)
    return (
        f"(same hit/miss {same_outcome.sum() / count:.5f}, "
        f"same t {close.sum() / max(both.sum(), 1):.5f})"
    )


if __name__ == "__main__":
    main()
