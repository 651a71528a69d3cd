#!/usr/bin/env python3
"""Per camera sample, yocto-hair against Cycles 5 and Mitsuba 3 on one of issue 36's cells:
CPU and error of one camera sample, with and without yocto-hair's per-pixel plan, where in the
image the error is (rings.py), and CPU against path depth.

    python3 scripts/bench/peer_per_sample.py --cell "curly e0.3 sun" [--yscene build/apps/yscene]
        [--ref-yscene PATH] [--work ~/.cache/yocto-hair/peers] [--seeds 3 4 5]
        [--sweep-spp 16] [--bounces 1 2 4 8 31] [--out docs/benchmark/per_sample-CELL.md]

The cell (256², 64 spp) must have been measured by peer_table.py (its references and the peers'
runs are read from --work, not rendered). yocto-hair renders it with its defaults and with
--no-adaptive (uniform sampling: one path a camera sample, the peers' way); all are scored as
compare.sh scores them (each against its own reference, less the reference's noise). Then the
depth sweep: yocto-hair uniform and Cycles 5 BLUE_NOISE at --sweep-spp, seed 3, at each
--bounces; the CPU of a camera sample at depth B, less that at the previous depth, is what the
paths still alive there cost. Run it on an idle machine: every CPU figure is a single run.
"""

import argparse
import datetime
import os
import re
import subprocess
import sys

BENCH = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, BENCH)
from peer_table import COMPARE, ROOT, SUNS, binary_id, cached, scene_dir  # noqa: E402

HERE = os.path.dirname(COMPARE)
RES, SPP, BOUNCES = 256, 64, 31


def run_in_peers_venv(work, script, arguments):
    """Runs a scoring script with the peers' venv (numpy, Mitsuba's EXR reader); returns stdout."""
    env = dict(os.environ, HOME=os.path.join(work, "home"))
    return subprocess.run([os.path.join(work, "venv", "bin", "python"), script] + arguments,
                          check=True, capture_output=True, text=True, env=env).stdout


def render_ours(yscene, scene, out, spp, seed, bounces, flags):
    """Renders out.exr with yscene and writes out.cpu; returns (CPU-s, rays)."""
    if not os.path.exists(out + ".cpu"):
        stats = subprocess.run(
            [yscene, "render", os.path.join(scene, "yocto", "scene.json"), "--output", out + ".exr",
             "--samples", str(spp), "--seed", str(seed), "--resolution", str(RES), "--threads", "2",
             "--bounces", str(bounces), "--clamp", "0", "--quiet", "--stats"] + flags,
            check=True, capture_output=True, text=True).stdout
        cpu = re.search(r"render_cpu=([0-9.]+)", stats).group(1)
        rays = re.search(r" rays=([0-9]+)", stats).group(1)
        with open(out + ".cpu.tmp", "w") as f:
            f.write(f"{cpu} {rays}\n")
        os.replace(out + ".cpu.tmp", out + ".cpu")
    cpu, rays = open(out + ".cpu").read().split()
    return float(cpu), int(rays)


def render_cycles(work, scene, eumelanin, sun, out, spp, seed, bounces):
    """Renders out.exr with Cycles 5 (BLUE_NOISE) as compare.sh does; returns CPU-s."""
    if not os.path.exists(out + ".cpu"):
        sigma_a = ",".join("%.6g" % (float(eumelanin) * a) for a in (0.419, 0.697, 1.37))
        command = [os.path.join(work, "bpy", "bin", "python"), os.path.join(HERE, "render_cycles.py"),
                   "--", "--strands", os.path.join(scene, "strands.json"), "--spp", str(spp),
                   "--res", str(RES), "--out", out + ".exr", "--threads", "2", "--seed", str(seed),
                   "--sampling-pattern", "BLUE_NOISE", "--param", "ABSORPTION", "--sigma-a", sigma_a,
                   "--roughness", "0.3", "--radial-roughness", "0.3", "--ior", "1.55",
                   "--offset-deg", "2", "--max-bounces", str(bounces)]
        if sun:
            direction, strength = sun.rsplit(",", 1)
            command += ["--sun-strength", strength, f"--sun-dir={direction}"]
        log = subprocess.run(command, check=True, capture_output=True, text=True).stdout
        cpu = re.findall(r"^render_cpu_seconds: ([0-9.]+)", log, re.M)[-1]
        with open(out + ".cpu.tmp", "w") as f:
            f.write(cpu + "\n")
        os.replace(out + ".cpu.tmp", out + ".cpu")
    return float(open(out + ".cpu").read().split()[0])


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cell", required=True, help='e.g. "curly e0.3 sun" (variant, eumelanin, light)')
    parser.add_argument("--yscene", default=os.path.join(ROOT, "build", "apps", "yscene"))
    parser.add_argument("--ref-yscene", default="", help="yscene whose references peer_table.py used")
    parser.add_argument("--work", default=os.path.expanduser("~/.cache/yocto-hair/peers"))
    parser.add_argument("--ref-spp", type=int, default=512)
    parser.add_argument("--seeds", nargs="*", default=["3", "4", "5"])
    parser.add_argument("--sweep-spp", type=int, default=16)
    parser.add_argument("--bounces", nargs="*", type=int, default=[1, 2, 4, 8, 31])
    parser.add_argument("--out", default="", help="default: docs/benchmark/per_sample-CELL.md")
    args = parser.parse_args()
    match = re.fullmatch(r"(straight|curly) e([0-9.]+) (sky|sun|low sun)", args.cell)
    if not match:
        sys.exit(f"peer_per_sample.py: --cell {args.cell!r}: want 'VARIANT eE LIGHT', e.g. 'curly e0.3 sun'")
    variant, eumelanin, light = match.groups()
    if not args.out:
        args.out = os.path.join(ROOT, "docs", "benchmark",
                                f"per_sample-{args.cell.replace(' ', '-')}.md")
    sun = SUNS[light]
    yscene = os.path.abspath(args.yscene)
    ref_yscene = os.path.abspath(args.ref_yscene) if args.ref_yscene else yscene
    scene = scene_dir(args.work, variant, eumelanin, sun)
    seeds = " ".join(args.seeds)
    if not cached(args.work, variant, eumelanin, sun, RES, SPP, seeds, args.ref_spp):
        sys.exit(f"peer_per_sample.py: the cell {args.cell!r} has no kept references and peers' runs "
                 f"in {scene} (measure it with peer_table.py first)")
    refs = os.path.join(scene, f"refs-r{RES}-b{BOUNCES}-n{args.ref_spp}")
    runs = os.path.join(scene, f"runs-r{RES}-b{BOUNCES}-s{SPP}")
    ours_ref = os.path.join(refs, f"yocto-{binary_id(ref_yscene)}")
    if not os.path.exists(ours_ref + "-A.exr") or not os.path.exists(ours_ref + "-B.exr"):
        sys.exit(f"peer_per_sample.py: no yocto-hair reference {ours_ref}-A/B.exr (give --ref-yscene)")
    mine = os.path.join(scene, "per-sample")
    os.makedirs(mine, exist_ok=True)
    binary = binary_id(yscene)

    # Error and CPU per camera sample at full depth.
    rows = []
    for seed in args.seeds:
        for name, flags in [("yocto-hair", []), ("yocto-hair uniform", ["--no-adaptive"])]:
            out = os.path.join(mine, f"yocto-{binary}-{'plan' if not flags else 'uniform'}-{seed}")
            print(f"{name}, seed {seed}...", file=sys.stderr, flush=True)
            render_ours(yscene, scene, out, SPP, seed, BOUNCES, flags)
            rows.append((name, out, ours_ref))
        for sampler in ["independent", "multijitter", "orthogonal"]:
            rows.append((f"mitsuba {sampler}", os.path.join(runs, f"mitsuba-{sampler}-{seed}"),
                         os.path.join(refs, "mitsuba")))
        for pattern in ["tsobol", "blue", "auto"]:
            rows.append((f"cycles5 {pattern}", os.path.join(runs, f"cycles5-{pattern}-{seed}"),
                         os.path.join(refs, "cycles5")))
    # score.py takes "NAME RUN REF" split at spaces: names without them.
    score_args = [f"{name.replace(' ', '-')} {run} {ref}" for name, run, ref in rows]
    scored = run_in_peers_venv(args.work, os.path.join(HERE, "score.py"), score_args)
    samples = RES * RES * SPP
    table = []
    for line in scored.splitlines():
        fields = line.split()
        if len(fields) == 6 and fields[1].isdigit():
            name, _, mse, _, cpu, efficiency = fields
            table.append((name, float(mse), float(cpu), float(efficiency)))
    best_peer = max((row for row in table if not row[0].startswith("yocto")), key=lambda r: r[3])

    # Where the error is: MSE in rings about the centre, ours against the best peer's.
    ringed = ["yocto-hair", "yocto-hair-uniform", best_peer[0]]
    ring_args = [arg for arg in score_args if arg.split()[0] in ringed]
    ring_rows = [line.split() for line in
                 run_in_peers_venv(args.work, os.path.join(BENCH, "rings.py"), ring_args).splitlines()]
    ring_bounds, ring_pixels = ring_rows[0][1:], [int(v) for v in ring_rows[1][1:]]
    ring_mse = {row[0]: [float(v) for v in row[1:]] for row in ring_rows[2:]}

    # CPU against depth.
    sweep = []
    for bounces in args.bounces:
        print(f"depth {bounces}...", file=sys.stderr, flush=True)
        ours_cpu, ours_rays = render_ours(
            yscene, scene, os.path.join(mine, f"sweep-yocto-{binary}-b{bounces}"), args.sweep_spp, 3,
            bounces, ["--no-adaptive"])
        cycles_cpu = render_cycles(args.work, scene, eumelanin, sun,
                                   os.path.join(mine, f"sweep-cycles5-b{bounces}"), args.sweep_spp, 3,
                                   bounces)
        sweep.append((bounces, ours_cpu, ours_rays, cycles_cpu))

    sweep_samples = RES * RES * args.sweep_spp
    lines = [
        f"# Per camera sample: {args.cell}, 256², yocto-hair against Cycles 5 and Mitsuba 3",
        "",
        f"`python3 scripts/bench/peer_per_sample.py --cell \"{args.cell}\"` ({datetime.date.today()}, "
        f"yscene sha256 {binary}; 2 threads; single runs). MSE and CPU-s as "
        f"`compare.sh` scores them (64 spp, seeds {seeds}: MSE averaged, CPU-s the median); µs a "
        "camera sample = CPU-s / (256² × 64); MSE × samples is the error one camera sample would "
        "have alone (lower is better).",
        "",
        "| renderer | MSE | CPU-s | efficiency | µs a camera sample | MSE × camera samples | efficiency × best peer |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, mse, cpu, efficiency in sorted(table, key=lambda r: -r[3]):
        lines.append(f"| {name} | {mse:.4g} | {cpu:.2f} | {efficiency:.1f} | {cpu / samples * 1e6:.2f} | "
                     f"{mse * samples:.4g} | {efficiency / best_peer[3]:.2f} |")
    lines += [
        "",
        f"Where the error is (`scripts/bench/rings.py`): MSE in rings about the image centre (radius "
        f"as a fraction of the half width; on the ball the centre shows strands end on, lit through "
        f"many fibres), against the best peer ({best_peer[0]}) in the same ring, and the share of "
        f"the image's error in each ring. CPU is the whole image's, so a ring's efficiency against "
        f"the peer is not these ratios alone.",
        "",
        "| ring | pixels | yocto-hair MSE / peer's | uniform MSE / peer's | yocto-hair share | uniform share | peer share |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    shares = {}
    for name in ringed:
        total = sum(m * n for m, n in zip(ring_mse[name], ring_pixels))
        shares[name] = [m * n / total for m, n in zip(ring_mse[name], ring_pixels)]
    for i, bounds in enumerate(ring_bounds):
        peer_mse = ring_mse[best_peer[0]][i]

        def ratio(name):
            return f"{ring_mse[name][i] / peer_mse:.2f}" if peer_mse > 0 else "–"
        lines.append(f"| {bounds} | {ring_pixels[i]} | {ratio('yocto-hair')} | {ratio('yocto-hair-uniform')} | "
                     f"{shares['yocto-hair'][i]:.2f} | {shares['yocto-hair-uniform'][i]:.2f} | "
                     f"{shares[best_peer[0]][i]:.2f} |")
    lines += [
        "",
        f"CPU against path depth ({args.sweep_spp} spp, seed 3; yocto-hair `--no-adaptive`, Cycles 5 "
        "BLUE_NOISE; Δ: the CPU of a camera sample added by the depths since the previous row):",
        "",
        "| max bounces | yocto-hair µs a camera sample | Δ | its rays a camera sample | Cycles 5 µs a camera sample | Δ | yocto-hair / Cycles 5 |",
        "|---:|---:|---:|---:|---:|---:|---:|",
    ]
    previous = (0.0, 0.0)
    for bounces, ours_cpu, ours_rays, cycles_cpu in sweep:
        ours_us, cycles_us = ours_cpu / sweep_samples * 1e6, cycles_cpu / sweep_samples * 1e6
        lines.append(f"| {bounces} | {ours_us:.2f} | {ours_us - previous[0]:.2f} | "
                     f"{ours_rays / sweep_samples:.2f} | {cycles_us:.2f} | {cycles_us - previous[1]:.2f} | "
                     f"{ours_us / cycles_us:.2f} |")
        previous = (ours_us, cycles_us)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out + ".tmp", "w") as f:
        f.write("\n".join(lines) + "\n")
    os.replace(args.out + ".tmp", args.out)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
