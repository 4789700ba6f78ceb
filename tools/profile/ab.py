#!/usr/bin/env python3
"""A/B timing of mobirt builds (or option sets) on a noisy machine.

Runs `BINARY render ARGS --timings --repeat R` for every variant in turn, ROUNDS times,
interleaved (A B C A B C ...), so that load from other processes hits every variant alike, and
prints the median over rounds of each stage (each run already reports the median of its R frames).

  tools/profile/ab.py --rounds 5 --repeat 5 A=build-a/mobirt B=build-b/mobirt -- SCENE -o /tmp/x.png [options]
  tools/profile/ab.py --rounds 5 'stack4=build/mobirt --stack 4' 'stack8=build/mobirt --stack 8' -- SCENE ...

Each variant is NAME=COMMAND: a binary, optionally followed by extra options. --csv FILE writes
every run (variant, round, stage, ms) for the printed stages.
"""
import argparse
import os
import shlex
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from timings import STAGE_KEYS, parse_timings  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--repeat", type=int, default=5, help="frames per run (mobirt --repeat)")
    parser.add_argument("--csv", help="write every run to this CSV file")
    parser.add_argument("--env", action="append", default=[], help="NAME=VALUE for every run")
    parser.add_argument("--stages", help="comma-separated stages to print instead of the default "
                        "(any of: %s)" % ",".join(STAGE_KEYS))
    parser.add_argument("variants", nargs="+", help="NAME=COMMAND ... -- RENDER ARGS")
    argv = sys.argv[1:]
    if "--" not in argv:
        parser.error("give the render arguments after --")
    cut = argv.index("--")
    args = parser.parse_args(argv[:cut])
    if args.stages:
        unknown = [x for x in args.stages.split(",") if x.strip() not in STAGE_KEYS]
        if unknown:
            parser.error("unknown stage(s) %s; choose from %s" % (", ".join(unknown), ",".join(STAGE_KEYS)))
    variants = [v.split("=", 1) for v in args.variants]
    render_args = argv[cut + 1:]
    env = dict(os.environ)
    for e in args.env:
        k, v = e.split("=", 1)
        env[k] = v
    runs = {name: [] for name, _ in variants}
    for r in range(args.rounds):
        for name, command in variants:
            cmd = shlex.split(command)
            cmd = [cmd[0], "render"] + render_args + cmd[1:] + ["--timings", "--repeat", str(args.repeat)]
            out = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if out.returncode != 0:
                sys.exit(f"{name}: {' '.join(cmd)} failed:\n{out.stderr}")
            runs[name].append(parse_timings(out.stdout))
            sys.stderr.write(f"\rround {r + 1}/{args.rounds} {name}   ")
    sys.stderr.write("\n")
    stages = [x.strip() for x in args.stages.split(",")] if args.stages else ["build", "traversal", "read-back", "decoding", "shading", "frame"]
    if "traversal" not in stages:
        stages.append("traversal")  # the Mrays/s and the ratio need it
    print("%-12s" % "variant" + "".join("%12s" % s for s in stages) + "%10s" % "Mrays/s" + "  (median of %d rounds)" % args.rounds)
    base = None
    for name, _ in variants:
        med = {s: statistics.median(t[s] for t in runs[name]) for s in stages}
        rays = runs[name][0]["rays"] + runs[name][0]["shadow_rays"]
        mrays = rays / (med["traversal"] * 1e3) if med["traversal"] > 0 else 0.0
        line = "%-12s" % name + "".join("%12.2f" % med[s] for s in stages) + "%10.2f" % mrays
        if base is None:
            base = med["traversal"]
        else:
            line += "  traversal x%.2f" % (base / med["traversal"])
        print(line)
    if args.csv:
        with open(args.csv, "w") as f:
            f.write("variant,round,stage,ms\n")
            for name, _ in variants:
                for i, t in enumerate(runs[name]):
                    for s in stages:
                        f.write(f"{name},{i},{s},{t[s]}\n")


if __name__ == "__main__":
    main()
