#!/usr/bin/env python3
"""ganache against SPlisHSPlasH on the anchor scenes, side by side: time per simulated second, solver iterations and
the accuracy of the result, measured the same way for both (anchor_metrics).

The scenes are ../shared/anchors (the same physical scene for both programs; ANCHORS points elsewhere). SPlisHSPlasH
is built outside this repository (../shared/anchors/README.md says how); ganache never depends on it.

  SPH=/path/to/SPHSimulator SPH_DATA=/path/to/SPlisHSPlasH/data benchmarks/anchors.py [SCENE ...]

Environment: GANACHE (default build/src/ganache), METRICS (default build/benchmarks/anchor_metrics), THREADS
(default 1), REPS (default 2), OUT (default out/anchors), VARIANTS (ganache scene variants, default "default"; the
anchors also have "matched"), PIN (a CPU list for `taskset -c`: the timed runs of both programs stay on those cores;
with THREADS=1 an unpinned run was at times 35 % slower on this project's 2-core machine, on every other launch in one
series, which runs by turns can hand to one program). Runs are interleaved (SPlisHSPlasH, then each ganache variant, per
repetition), so a change of machine load hits both. The reference for accuracy is ganache at tight tolerances and fixed 0.5 ms steps
(run once per scene, not timed); errors are the relative differences of the spread and of the centroid height. Time
ratios are the medians' ratio and, beside it, the range of each repetition's ratio to SPlisHSPlasH's run of the same
repetition. SPlisHSPlasH samples its boundaries at random, and its buckling run's cost moves with the samples (222 to
243 steps, 0.46 to 0.57 of its time for ganache's on 1 thread in one session's samples): each repetition gets samples
of its own, drawn once per OUT folder, and every other column is the median over the repetitions.
"""
import glob
import json
import os
import re
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ANCHORS = os.environ.get("ANCHORS", os.path.join(ROOT, "..", "shared", "anchors"))
GANACHE = os.environ.get("GANACHE", os.path.join(ROOT, "build", "src", "ganache"))
METRICS = os.environ.get("METRICS", os.path.join(ROOT, "build", "benchmarks", "anchor_metrics"))
SPH = os.environ.get("SPH")
SPH_DATA = os.environ.get("SPH_DATA")
THREADS = int(os.environ.get("THREADS", "1"))
REPS = int(os.environ.get("REPS", "2"))
OUT = os.path.abspath(os.environ.get("OUT", os.path.join(ROOT, "out", "anchors")))
VARIANTS = os.environ.get("VARIANTS", "default").split()
PIN = os.environ.get("PIN")
SCENES = sys.argv[1:] or ["block8k_01", "buckling", "block50k"]


def scene_facts(scene):
    """Particle radius and rest density of the anchor scene, from its SPlisHSPlasH file."""
    text = open(os.path.join(ANCHORS, "splishsplash", scene + ".json")).read()
    radius = float(re.search(r'"particleRadius":\s*([\d.eE+-]+)', text).group(1))
    rho0 = float(re.search(r'"density0":\s*([\d.eE+-]+)', text).group(1))
    stop = float(re.search(r'"stopAt":\s*([\d.eE+-]+)', text).group(1))
    return radius, rho0, stop


def metrics(path, radius, rho0, mass):
    out = subprocess.run([METRICS, "--radius", str(radius), "--rho0", str(rho0), "--mass", mass, "--floor", "0", path],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def pinned(command):
    return ["taskset", "-c", PIN] + command if PIN else command


def run_ganache(scene_file, out, threads):
    base = [GANACHE, None, scene_file, "--out", out, "--quality", "final", "--threads", str(threads),
            "--skip-resource-check"]
    subprocess.run([base[0], "sample"] + base[2:], check=True, capture_output=True)
    start = time.monotonic()
    subprocess.run(pinned([base[0], "simulate"] + base[2:]), check=True, capture_output=True)
    wall = time.monotonic() - start
    report = json.load(open(os.path.join(out, "report.json")))
    steps = report["steps"]
    solver = report["solver"]
    loop = report["per_step_ms"]["total"] * steps / 1000
    return dict(wall=wall, loop=loop, sim=report["simulated_time_s"], steps=steps,
                ms_step=report["per_step_ms"]["total"], n=report["particles"]["fluid"],
                p_it=solver["pressure_iterations_per_step"] + solver["divergence_iterations_per_step"],
                v_it=solver.get("viscosity_iterations_per_solve", 0) * solver.get("viscosity_solves", 0) / max(steps, 1),
                final=sorted(glob.glob(os.path.join(out, "particles", "*.vdb")))[-1])


def run_sph(scene, out, threads, rep):
    text = open(os.path.join(ANCHORS, "splishsplash", scene + ".json")).read().replace("@SPH_DATA@", SPH_DATA)
    os.makedirs(out, exist_ok=True)
    # SPlisHSPlasH samples its boundaries at random (Poisson disk) and caches the samples beside the scene: one scene
    # folder per repetition, so that each repetition runs on samples of its own (kept for the next run with this OUT).
    scene_file = os.path.join(OUT, "scenes", f"r{rep}", scene + ".json")
    os.makedirs(os.path.dirname(scene_file), exist_ok=True)
    if not os.path.exists(scene_file) or open(scene_file).read() != text:
        open(scene_file, "w").write(text)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads))
    marker = scene_file + ".cached"
    if not os.path.exists(marker):  # SPlisHSPlasH caches its boundary samples beside the scene: fill it untimed
        subprocess.run([SPH, "--no-gui", "--no-initial-pause", "--param", "stopAt:0.001", "--output-dir",
                        os.path.join(out, "warmup"), scene_file], env=env, capture_output=True)
        open(marker, "w").close()
    start = time.monotonic()
    log = subprocess.run(pinned([SPH, "--no-gui", "--no-initial-pause", "--output-dir", out, scene_file]), env=env,
                         capture_output=True, text=True).stdout
    wall = time.monotonic() - start
    average = {k: float(v) for k, v in re.findall(r"Average time: (.+?): ([\d.eE+-]+) ms", log)}
    total = {k: float(v) for k, v in re.findall(r"Time sum: (.+?): ([\d.eE+-]+) ms", log)}
    count = {k: float(v) for k, v in re.findall(r"Average number: (.+?): ([\d.eE+-]+)", log)}
    steps = round(total["SimStep"] / average["SimStep"])
    vtks = sorted(glob.glob(os.path.join(out, "vtk", "ParticleData_Fluid_*.vtk")),
                  key=lambda f: int(re.search(r"_(\d+)\.vtk$", f).group(1)))
    return dict(wall=wall, loop=total["SimStep"] / 1000, sim=None, steps=steps, ms_step=average["SimStep"], n=None,
                p_it=count.get("DFSPH - iterations", 0) + count.get("DFSPH - iterationsV", 0),
                v_it=count.get("Visco iterations", 0), final=vtks[-1])


def reference(scene, radius, rho0):
    """ganache at tight tolerances and 0.5 ms steps: the converged answer the others are measured against."""
    out = os.path.join(OUT, "reference", scene)
    final = sorted(glob.glob(os.path.join(out, "particles", "*.vdb")))
    if not final:
        text = open(os.path.join(ANCHORS, "ganache", scene + "_default.yaml")).read()
        text = text.replace("checkpoint_every: 0", "checkpoint_every: 0\n  time_step: {fixed: 0.0005}\n"
                            "  pressure: {density_error: 0.001, divergence_error: 0.01, max_iterations: 10000}")
        text = re.sub(r"viscosity: \{boundary_mu: ([\d.eE+-]+)\}",
                      r"viscosity: {boundary_mu: \1, tolerance: 1.0e-6, max_iterations: 10000}", text)
        os.makedirs(out, exist_ok=True)
        scene_file = os.path.join(out, scene + "_reference.yaml")
        open(scene_file, "w").write(text)
        run_ganache(scene_file, out, os.cpu_count())
        final = sorted(glob.glob(os.path.join(out, "particles", "*.vdb")))
    return metrics(final[-1], radius, rho0, "lattice")


def main():
    if not (SPH and SPH_DATA):
        sys.exit("set SPH (the SPHSimulator binary) and SPH_DATA (its data folder); see ../shared/anchors/README.md")
    rows = []
    for scene in SCENES:
        radius, rho0, stop = scene_facts(scene)
        ref = reference(scene, radius, rho0)
        runs = {}
        for rep in range(REPS):
            r = run_sph(scene, os.path.join(OUT, "sph", scene, f"r{rep}"), THREADS, rep)
            r["sim"] = stop
            r["shape"] = metrics(r["final"], radius, rho0, "splishsplash")
            runs.setdefault("SPlisHSPlasH", []).append(r)
            for variant in VARIANTS:
                out = os.path.join(OUT, "ganache_" + variant, scene, f"r{rep}")
                r = run_ganache(os.path.join(ANCHORS, "ganache", f"{scene}_{variant}.yaml"), out, THREADS)
                r["shape"] = metrics(r["final"], radius, rho0, "lattice")
                runs.setdefault("ganache " + variant, []).append(r)
            print(f"{scene} repetition {rep + 1}/{REPS} done", file=sys.stderr)
        sph_loop = statistics.median(r["loop"] / r["sim"] for r in runs["SPlisHSPlasH"])
        for program, rs in runs.items():
            loop = statistics.median(r["loop"] / r["sim"] for r in rs)
            # each repetition against SPlisHSPlasH's run of the same repetition, which ran just before it
            paired = [(r["loop"] / r["sim"]) / (s["loop"] / s["sim"]) for r, s in zip(rs, runs["SPlisHSPlasH"])]
            n = rs[0]["shape"]["n"]

            def med(f):  # the median over the repetitions (SPlisHSPlasH's differ with their boundary samples)
                return statistics.median(f(r) for r in rs)

            def shape(key):
                return med(lambda r: r["shape"][key])

            rows.append([scene, program, n, f"{loop:.2f}", f"{loop / sph_loop:.2f}",
                         f"{min(paired):.2f}-{max(paired):.2f}", f"{med(lambda r: r['ms_step']):.1f}",
                         f"{med(lambda r: r['steps']):.0f}",
                         f"{1e6 * med(lambda r: r['loop'] / r['steps']) * THREADS / n:.2f}",
                         f"{med(lambda r: r['p_it']):.1f}", f"{med(lambda r: r['v_it']):.1f}",
                         f"{100 * shape('compression_mean'):.3f} / {100 * shape('compression_p999'):.2f} / "
                         f"{100 * shape('compression_max'):.2f}", f"{100 * shape('bulk_density_error_median'):+.2f}",
                         f"{100 * med(lambda r: abs(r['shape']['spread_m'] / ref['spread_m'] - 1)):.2f}",
                         f"{100 * med(lambda r: abs(r['shape']['centroid'][1] / ref['centroid'][1] - 1)):.2f}"])
    header = ["scene", "program", "fluid particles", "s per simulated s", "vs SPlisHSPlasH",
              "vs SPlisHSPlasH, each repetition", "ms per step", "steps",
              "core-us per particle-step", "pressure it/step", "viscosity CG it/step",
              "compression mean / 99.9th percentile / max [%]", "bulk density error [%]", "spread error [%]",
              "centroid height error [%]"]
    print(f"\n{THREADS} thread(s), median of {REPS} runs (SPlisHSPlasH: each on boundary samples of its own); errors "
          "against ganache at tight tolerances and 0.5 ms steps\n")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    for r in rows:
        print("| " + " | ".join(str(c) for c in r) + " |")


if __name__ == "__main__":
    main()
