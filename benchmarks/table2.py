#!/usr/bin/env python3
"""The rows of Weiler et al. 2018, Table 2 on this machine: milliseconds per step by part, CG iterations per viscosity
solve, beside the paper's figures (2 x 18-core Xeon E5-2697).

  benchmarks/table2.py [ROW ...]        rows: grid bunny5 bunny0.5 bunny0.05 bunny100k bunny200k statue

Each row is a variant of a scene in scenes/ at the paper's particle count, time step and viscosity, simulated for
STEPS steps (default 20) from its first contact with the floor (the bunny and the statue start on it at 1 m/s, so
every measured step has an impact's work); the paper averages whole animations, so its early free fall and its calm
end are in its figures and not here: STEPS=200 or 2000 measure more of what follows the impact (docs/benchmarks.md,
"Longer windows"). Environment: GANACHE (default build/src/ganache), THREADS (default 2), STEPS, OUT (default
out/table2). The coiling (25k) and buckling (80k) rows are emitter scenes that reach the paper's counts only after
seconds of simulated time; they are not measured here but by running their scenes at final quality (docs/paper.md).
"""
import json
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GANACHE = os.environ.get("GANACHE", os.path.join(ROOT, "build", "src", "ganache"))
THREADS = int(os.environ.get("THREADS", "2"))
STEPS = int(os.environ.get("STEPS", "20"))
OUT = os.path.abspath(os.environ.get("OUT", os.path.join(ROOT, "out", "table2")))

# The bunny of scenes/bunny_grid.yaml holds 49,905 particles at its final radius: rows scale the radius to the paper's
# counts.
def bunny(count):
    return (49905 / count) ** (1 / 3)


# name: (scene, dt [s], radius factor on the scene's final radius, mu, paper's row: particles, CG iterations,
# total [ms])
ROWS = {
    "grid": ("bunny_grid", 1e-3, bunny(56e3), 15000, ("56k", 10.4, 123.8)),
    "bunny5": ("bunny", 5e-3, bunny(56e3), 10000, ("56k", 23.8, 184.5)),
    "bunny0.5": ("bunny", 5e-4, bunny(56e3), 10000, ("56k", 6.7, 85.6)),
    "bunny0.05": ("bunny", 5e-5, bunny(56e3), 10000, ("56k", 1, 54.2)),
    "bunny100k": ("bunny", 5e-4, bunny(100e3), 10000, ("100k", 16.3, 262.9)),
    "bunny200k": ("bunny", 5e-4, bunny(200e3), 10000, ("200k", 21.1, 571.5)),
    "statue": ("statue", 5e-4, 1.0, 20000, ("1.1M", 10.3, 2188.8)),
}


def scene_text(row, kind, dt, mu):
    """The scene of a row: the grid scene with its bunny lowered onto the bars, or its bunny on a bare floor, or the
    statue lowered onto its floor, each resting on it at 1 m/s down. The time step is fixed and a frame holds STEPS
    steps."""
    name = "statue" if kind == "statue" else "bunny_grid"
    text = open(os.path.join(ROOT, "scenes", name + ".yaml")).read()
    text = re.sub(r"^(#[^\n]*\n)+", f"# benchmarks/table2.py, row {row}: made from scenes/{name}.yaml\n", text)
    text = re.sub(r"\nname: \w+", "\nname: " + row.replace(".", "_"), text)
    mesh_dir = os.path.join(ROOT, "assets")
    text = text.replace("../assets", mesh_dir)
    fps = 1 / (STEPS * dt)
    text = re.sub(r"frames: \{[^}]*\}[^\n]*", f"frames: {{fps: {fps:.6g}, start: 1, end: 2}}", text)
    text = re.sub(r"viscosity: \{mu: [\d.eE+-]+", f"viscosity: {{mu: {mu}", text)
    text = text.replace("\neffects:", f"\nsimulation: {{time_step: {{fixed: {dt}}}, checkpoint_every: 0}}\n\neffects:")
    text = re.sub(r"\nsurface:.*", "", text, flags=re.S)  # the solver only
    if kind == "statue":
        # From the scene's 5 mm above the floor the statue would fall freely through the measured steps: a body moving
        # as one has no viscous work (0 CG iterations a solve).
        text = text.replace("base: [0, 0.005, 0]}", "base: [0, 0.002, 0]}")
    else:
        # Dropped from the scene's 6 cm above the bars the bunny would still be falling freely after STEPS steps.
        if kind == "bunny":
            text = re.sub(r"\n  - \{name: grid, bars:[^\n]*", "", text)
        base = "0.002" if kind == "bunny" else "0.107"  # the bars' tops are at 0.106 m
        text = text.replace("base: [0, 0.16, 0]}", f"base: [0, {base}, 0]}}")
    return text.replace("    material: honey\n", "    material: honey\n    velocity: [0, -1, 0]\n")


def run(row):
    kind, dt, factor, mu, paper = ROWS[row]
    out = os.path.join(OUT, row)
    os.makedirs(out, exist_ok=True)
    scene = os.path.join(out, f"{row.replace('.', '_')}.yaml")
    open(scene, "w").write(scene_text(row, kind, dt, mu))
    quality = "final" if factor == 1.0 else f"{factor:.6g}"
    common = ["--out", out, "--quality", quality, "--threads", str(THREADS), "--skip-resource-check"]
    subprocess.run([GANACHE, "sample", scene] + common, check=True, capture_output=True)
    subprocess.run([GANACHE, "simulate", scene] + common, check=True, capture_output=True)
    report = json.load(open(os.path.join(out, "report.json")))
    ms = report["per_step_ms"]
    solver = report["solver"]
    return dict(row=row, n=report["particles"]["fluid"], dt=dt, mu=mu, steps=report["steps"],
                neighbours=ms["neighbours"], pressure=ms["pressure"] + ms["divergence"],
                viscosity=ms.get("viscosity", 0), cg=solver.get("viscosity_iterations_per_solve", 0),
                total=ms["total"], paper=paper)


def main():
    rows = sys.argv[1:] or [r for r in ROWS if r != "statue"]
    for r in rows:
        if r not in ROWS:
            sys.exit(f"unknown row '{r}'; rows: {' '.join(ROWS)}")
    print(f"{THREADS} thread(s), {STEPS} steps a row from first contact; the paper: 36 cores, whole animations\n")
    header = ["scene", "dt [ms]", "particles", "mu [Pa s]", "neighbours [ms]", "pressure [ms]", "viscosity [ms]",
              "CG it/solve", "total [ms]", "core-us per particle-step", "paper: particles", "paper: CG it/solve",
              "paper: total [ms]", "paper: core-us per particle-step"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        m = run(r)
        p = m["paper"]
        paper_n = float(p[0][:-1]) * (1e6 if p[0].endswith("M") else 1e3)
        print("| " + " | ".join(str(c) for c in [
            m["row"], f"{1000 * m['dt']:g}", m["n"], m["mu"], f"{m['neighbours']:.1f}", f"{m['pressure']:.1f}",
            f"{m['viscosity']:.1f}", f"{m['cg']:.1f}", f"{m['total']:.1f}",
            f"{1000 * m['total'] * THREADS / m['n']:.2f}", p[0], p[1], p[2],
            f"{1000 * p[2] * 36 / paper_n:.2f}"]) + " |", flush=True)


if __name__ == "__main__":
    main()
