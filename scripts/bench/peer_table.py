#!/usr/bin/env python3
"""yocto-hair against Mitsuba 3 and Cycles 5 on the hair-ball cells of issue 36, side by side.

    python3 scripts/bench/peer_table.py [--yscene build/apps/yscene] [--ref-yscene PATH]
        [--work ~/.cache/yocto-hair/peers] [--ref-spp 512] [--cells SUBSTRING ...]
        [--cached-only] [--out docs/benchmark/peers.md]

Each cell is one run of ../shared/peers/mitsuba/compare.sh --cycles5 (the peers'
own script: the same strands, each renderer scored against its own converged
reference, efficiency = 1 / (MSE x render CPU-s), seeds 3 4 5, 2 threads) and a
row of the table: yocto-hair's MSE, CPU-s and efficiency, the best peer (the
best of Mitsuba's samplers and Cycles 5's patterns on that cell) and the
ratio. The cells: the straight and curly balls x eumelanin 0.3, 1.3 and 4 x the
white sky alone, with a sun (1,-1,2,3) and with a low sun (1,-1,0.35,3) at 256²,
64 spp; at 256 spp the eumelanin-1.3 balls with and without the first sun; the
straight ball at 512², 64 spp (seed 3). compare.sh keeps references and the
peers' runs in --work (outside the tree, so that later sessions reuse them):
the table can be built up cell by cell; --cached-only scores only the cells
whose references and peer runs are all there (rendering yocto-hair's runs).
A cell not scored in this run keeps its row from the CSV already at --out,
with the yscene that row was measured with (the yscene column), so a table
built up over sessions says which binary each row is.
The peers' timed runs are kept once made, so make them on an idle machine.
Writes --out (markdown) and the same rows as CSV beside it.
"""

import argparse
import csv
import datetime
import hashlib
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
COMPARE = os.path.join(ROOT, "..", "shared", "peers", "mitsuba", "compare.sh")
SUNS = {"sky": None, "sun": "1,-1,2,3", "low sun": "1,-1,0.35,3"}


def cells():
    """(name, compare.sh arguments) of every cell, in the table's order."""
    result = []
    for variant in ["straight", "curly"]:
        for eumelanin in ["0.3", "1.3", "4"]:
            for light, sun in SUNS.items():
                result.append((f"{variant} e{eumelanin} {light} 256² 64spp",
                               variant, eumelanin, sun, 256, 64, "3 4 5"))
    for variant in ["straight", "curly"]:
        for light in ["sky", "sun"]:
            result.append((f"{variant} e1.3 {light} 256² 256spp",
                           variant, "1.3", SUNS[light], 256, 256, "3 4 5"))
    result.append(("straight e1.3 sky 512² 64spp", "straight", "1.3", None, 512, 64, "3"))
    return result


def binary_id(path):
    """A binary's id as compare.sh keys its runs: the first 12 digits of its sha256."""
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()[:12]


def scene_dir(work, variant, eumelanin, sun):
    return os.path.join(work, f"scene-{variant}-20000-e{eumelanin}-p0" +
                        (f"-sun{sun.replace(',', '_')}" if sun else ""))


def cached(work, variant, eumelanin, sun, res, spp, seeds, ref_spp):
    """Whether the peers' references and runs of a cell are all kept."""
    scene = scene_dir(work, variant, eumelanin, sun)
    refs = os.path.join(scene, f"refs-r{res}-b31-n{ref_spp}")
    runs = os.path.join(scene, f"runs-r{res}-b31-s{spp}")
    names = [os.path.join(refs, f"{peer}-{half}.cpu") for peer in ["mitsuba", "cycles5"]
             for half in "AB"]
    for seed in seeds.split():
        names += [os.path.join(runs, f"mitsuba-{s}-{seed}.cpu")
                  for s in ["independent", "multijitter", "orthogonal"]]
        names += [os.path.join(runs, f"cycles5-{p}-{seed}.cpu") for p in ["tsobol", "blue", "auto"]]
    return all(os.path.exists(name) for name in names)


def previous_rows(out, markdown):
    """The rows of the CSV beside --out, by cell: (yscene, reference spp, ours, (peer, its
    figures)). A CSV without the yscene and ref_spp columns (older runs) takes the binary and
    the references its markdown's header (the text of --out, `markdown`) names."""
    path = os.path.splitext(out)[0] + ".csv"
    if not os.path.exists(path):
        return {}
    match = re.search(r"yscene sha256 ([0-9a-f]+)", markdown)
    header_binary = match.group(1) if match else "?"
    match = re.search(r"references 2 x (\d+) spp", markdown)
    header_refs = match.group(1) if match else "?"
    rows = {}
    with open(path, newline="", encoding="utf-8") as f:
        for row in csv.DictReader(f):
            ours = (float(row["mse"]), float(row["cpu_s"]), float(row["efficiency"]))
            peer = (float(row["peer_mse"]), float(row["peer_cpu_s"]), float(row["peer_efficiency"]))
            rows[row["cell"]] = (row.get("yscene") or header_binary,
                                 row.get("ref_spp") or header_refs, ours, (row["best_peer"], peer))
    return rows


ROW = re.compile(r"^(\S+)\s+(\d+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)$")


def run_cell(args, variant, eumelanin, sun, res, spp, seeds):
    command = ["bash", COMPARE, "--work", args.work, "--yscene", args.yscene, "--cycles5",
               "--variant", variant, "--eumelanin", eumelanin, "--res", str(res), "--spp", str(spp),
               "--seeds", seeds, "--ref-spp", str(args.ref_spp)]
    if args.ref_yscene:
        command += ["--ref-yscene", args.ref_yscene]
    if sun:
        command += ["--sun", sun]
    print("+", " ".join(command), file=sys.stderr, flush=True)
    output = subprocess.run(command, cwd=ROOT, check=True, capture_output=True, text=True).stdout
    rows = {}
    for line in output.splitlines():
        match = ROW.match(line.strip())
        if match and match.group(1) != "renderer":
            name, _, mse, _, cpu, efficiency = match.groups()
            rows[name] = (float(mse), float(cpu), float(efficiency))
    if "yocto-hair" not in rows or len(rows) < 2:
        sys.exit(f"peer_table.py: no table from compare.sh:\n{output}")
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--yscene", default=os.path.join(ROOT, "build", "apps", "yscene"))
    parser.add_argument("--ref-yscene", default="",
                        help="yscene whose defaults render yocto-hair's references (default: --yscene)")
    parser.add_argument("--work", default=os.path.expanduser("~/.cache/yocto-hair/peers"))
    parser.add_argument("--ref-spp", type=int, default=512, help="spp of each half of a reference")
    parser.add_argument("--cells", nargs="*", default=[], help="only cells whose name has one of these")
    parser.add_argument("--cached-only", action="store_true",
                        help="only cells whose peer references and runs are kept")
    parser.add_argument("--out", default=os.path.join(ROOT, "docs", "benchmark", "peers.md"))
    args = parser.parse_args()
    args.yscene = os.path.abspath(args.yscene)
    if args.ref_yscene:
        args.ref_yscene = os.path.abspath(args.ref_yscene)
    os.makedirs(args.work, exist_ok=True)
    binary = binary_id(args.yscene)
    markdown = ""
    if os.path.exists(args.out):
        with open(args.out, encoding="utf-8") as f:
            markdown = f.read()
    previous = previous_rows(args.out, markdown)
    table = []
    for name, variant, eumelanin, sun, res, spp, seeds in cells():
        # A cell left out by --cells or not kept for --cached-only keeps its earlier row.
        if (args.cells and not any(part in name for part in args.cells)) or (
                args.cached_only and not cached(args.work, variant, eumelanin, sun, res, spp,
                                                seeds, args.ref_spp)):
            table.append((name, previous.get(name)))
            continue
        rows = run_cell(args, variant, eumelanin, sun, res, spp, seeds)
        ours = rows["yocto-hair"]
        peer = max((row for row in rows.items() if row[0] != "yocto-hair"), key=lambda r: r[1][2])
        table.append((name, (binary, str(args.ref_spp), ours, peer)))
        print(f"{name}: {ours[2] / peer[1][2]:.2f}x {peer[0]}", file=sys.stderr, flush=True)
    lines = [
        "# yocto-hair against Mitsuba 3 and Cycles 5, side by side",
        "",
        f"`python3 scripts/bench/peer_table.py` (last run {datetime.date.today()} with yscene sha256 "
        f"{binary} and references of 2 x {args.ref_spp} spp each; seeds 3 4 5, 512² seed 3; 2 threads). "
        "Each cell is "
        "one run of `../shared/peers/mitsuba/compare.sh --cycles5`: MSE against the renderer's own "
        "reference less the reference's noise, render CPU-s the median of the runs, efficiency "
        "1 / (MSE x CPU-s); the best peer is the best of Mitsuba 3's `independent`, `multijitter` and "
        "`orthogonal` samplers and Cycles 5's `TABULATED_SOBOL`, `BLUE_NOISE` and `AUTOMATIC` patterns "
        "on that cell. Sun: a distant light from (1,-1,2), irradiance 3, beside the white sky; low "
        "sun: from (1,-1,0.35). The yscene column is the sha256 of the binary a row was measured "
        "with and refs the spp of each half of its references (rows kept from earlier runs keep "
        "theirs); a cell marked 'not run' has no row yet.",
        "",
        "| cell | yscene | refs | yocto-hair MSE | CPU-s | efficiency | best peer | its MSE, CPU-s, efficiency | x best peer |",
        "|---|---|---:|---:|---:|---:|---|---:|---:|",
    ]
    records = []
    for name, result in table:
        if result is None:
            lines.append(f"| {name} | not run | | | | | | | |")
            continue
        yscene, refs, (mse, cpu, efficiency), (peer, (pmse, pcpu, peff)) = result
        lines.append(f"| {name} | {yscene} | {refs} | {mse:.4g} | {cpu:.2f} | {efficiency:.0f} | {peer} | "
                     f"{pmse:.4g}, {pcpu:.2f}, {peff:.0f} | **{efficiency / peff:.2f}** |")
        records.append([name, yscene, refs, mse, cpu, efficiency, peer, pmse, pcpu, peff,
                        efficiency / peff])
    # What follows a '## Notes' heading in the existing table is written by
    # hand (how the rows were measured, over which sessions): kept as it is.
    notes = markdown.find("\n## Notes\n")
    if notes >= 0:
        lines += [""] + markdown[notes + 1:].rstrip("\n").split("\n")
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    for path, write in [(args.out, lambda f: f.write("\n".join(lines) + "\n")),
                        (os.path.splitext(args.out)[0] + ".csv",
                         lambda f: csv.writer(f).writerows(
                             [["cell", "yscene", "ref_spp", "mse", "cpu_s", "efficiency",
                               "best_peer", "peer_mse", "peer_cpu_s", "peer_efficiency",
                               "ratio"]] + records))]:
        with open(path + ".tmp", "w", newline="") as f:
            write(f)
        os.replace(path + ".tmp", path)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
