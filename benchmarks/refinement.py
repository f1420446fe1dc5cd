#!/usr/bin/env python3
"""Requirement R3 under spatial refinement (Weiler et al. 2018, Fig. 10: the bunny at 56k, 100k and 200k particles
behaves the same): the study's viscous bunny (scenes/study/viscous_bunny.yaml, 100 Pa s dropped on the ground, 0.5 s)
at several particle counts, each run's final shape measured by anchor_metrics.

  benchmarks/refinement.py [COUNT ...]        default: 56000 100000 200000

Each count is reached by scaling the scene's final radius by the cube root of (its final count / COUNT); the sampled
count lands within a few per cent of it. Prints, per run: particles, radius, steps, wall time, spread (RMS horizontal
distance from the centroid's vertical), centroid height, mean and largest compression, and the spread's and height's
differences from the finest run. Environment: GANACHE (default build/src/ganache), METRICS (default
build/benchmarks/anchor_metrics), THREADS (default 2), OUT (default out/refinement).
"""
import glob
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GANACHE = os.environ.get("GANACHE", os.path.join(ROOT, "build", "src", "ganache"))
METRICS = os.environ.get("METRICS", os.path.join(ROOT, "build", "benchmarks", "anchor_metrics"))
THREADS = int(os.environ.get("THREADS", "2"))
OUT = os.path.abspath(os.environ.get("OUT", os.path.join(ROOT, "out", "refinement")))
SCENE = os.path.join(ROOT, "scenes", "study", "viscous_bunny.yaml")
RHO0 = 1420  # the scene's batter is honey (materials.cpp) with its viscosity changed


def ganache(command, out, quality):
    subprocess.run([GANACHE, command, SCENE, "--out", out, "--quality", quality, "--threads", str(THREADS),
                    "--skip-resource-check"], check=True, capture_output=True)
    return json.load(open(os.path.join(out, "report.json")))


def final_count():
    """Particles the scene samples at its final radius (sampling only)."""
    out = os.path.join(OUT, "final_sample")
    report = ganache("sample", out, "final")
    return report["particles"]["fluid"], report["particle_radius_m"]


def run(count, base_count, base_radius):
    factor = (base_count / count) ** (1 / 3)
    out = os.path.join(OUT, f"n{count}")
    ganache("sample", out, f"{factor:.6g}")
    report = ganache("simulate", out, f"{factor:.6g}")
    radius = report["particle_radius_m"]
    last = sorted(glob.glob(os.path.join(out, "particles", "*.vdb")))[-1]
    shape = json.loads(subprocess.run([METRICS, "--radius", str(radius), "--rho0", str(RHO0), "--mass", "lattice",
                                       "--floor", "0", last], check=True, capture_output=True, text=True).stdout)
    return dict(n=report["particles"]["fluid"], radius=radius, steps=report["steps"], wall=report["wall_s"],
                spread=shape["spread_m"], height=shape["centroid"][1], mean=shape["compression_mean"],
                worst=shape["compression_max"])


def main():
    counts = [int(c) for c in sys.argv[1:]] or [56000, 100000, 200000]
    base_count, base_radius = final_count()
    runs = []
    for c in counts:
        runs.append(run(c, base_count, base_radius))
        print(f"{runs[-1]['n']} particles done", file=sys.stderr, flush=True)
    finest = min(runs, key=lambda r: r["radius"])
    print(f"{THREADS} thread(s); scenes/study/viscous_bunny.yaml (0.5 s); differences against the finest run\n")
    header = ["particles", "radius [mm]", "steps", "wall [s]", "spread [mm]", "centroid height [mm]",
              "compression mean / max [%]", "spread difference [%]", "height difference [%]"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in runs:
        print("| " + " | ".join([
            f"{r['n']:,}", f"{1000 * r['radius']:.3f}", str(r["steps"]), f"{r['wall']:.0f}", f"{1000 * r['spread']:.2f}",
            f"{1000 * r['height']:.2f}", f"{100 * r['mean']:.4f} / {100 * r['worst']:.2f}",
            f"{100 * (r['spread'] / finest['spread'] - 1):+.2f}",
            f"{100 * (r['height'] / finest['height'] - 1):+.2f}"]) + " |")


if __name__ == "__main__":
    main()
