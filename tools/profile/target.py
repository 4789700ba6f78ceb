#!/usr/bin/env python3
"""Where the traversal pass stands against Embree on the same rays (issue 5's traversal target:
at least 0.5x Embree rtcIntersect1 in Mrays/s, 2 threads).

  tools/profile/target.py [--rounds 5] [--mobirt build/mobirt] [--embree build/mobirt_embree_rays]
                          [-- SCENE and view options]

Alternates, ROUNDS times, `mobirt render ... --timings-json` (the traversal pass's Mrays/s, median
of 5 frames, primary + shadow rays, the primaries traced: --primary trace) and `mobirt_embree_rays` on the same scene, view and rays
(median of 5 runs of rtcIntersect1 on every ray), so that both see the same machine load, and
prints the medians and their ratio. Default scene: the Utah toasters with the README's view.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SHARED = os.environ.get("MOBIRT_SHARED_SCENES", os.path.join(ROOT, "..", "..", "shared", "scenes"))
if not os.path.isdir(SHARED):
    SHARED = os.path.join(ROOT, "..", "shared", "scenes")
UTAH = [os.path.join(SHARED, "utah-toasters", "Toasters004.obj"), "--camera", "0,260,480:0,20,0:0,1,0:40",
        "--light", "point pos=150,500,300 intensity=300000"]


def main():
    argv = sys.argv[1:]
    scene = UTAH
    if "--" in argv:
        cut = argv.index("--")
        scene = argv[cut + 1:]
        argv = argv[:cut]
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--mobirt", default=os.path.join(ROOT, "build", "mobirt"))
    parser.add_argument("--embree", default=os.path.join(ROOT, "build", "mobirt_embree_rays"))
    args = parser.parse_args(argv)
    ours, embree, ms = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            js = os.path.join(tmp, "t.json")
            subprocess.run([args.mobirt, "render"] + scene + ["-o", os.path.join(tmp, "t.png"), "--depth", "0",
                                                              "--primary", "trace",
                                                              "--timings-json", js, "--repeat", "5"],
                           check=True, capture_output=True)
            with open(js) as f:
                m = json.load(f)["median"]
            ours.append(m["trace_mrays"])
            ms.append(m["trace_ms"])
            out = subprocess.run([args.embree] + scene + ["--repeat", "5"], check=True, capture_output=True,
                                 text=True).stdout
            line = next(l for l in out.splitlines() if l.startswith("intersect1 "))
            embree.append(float(line.split("ms")[1].split()[0]))
            sys.stderr.write(f"\rround {r + 1}/{args.rounds}: traversal pass {ours[-1]:.2f}, Embree {embree[-1]:.2f} Mrays/s")
    sys.stderr.write("\n")
    a, b = statistics.median(ours), statistics.median(embree)
    print(f"traversal pass (lavapipe, primary + shadow rays): {statistics.median(ms):.2f} ms, {a:.2f} Mrays/s")
    print(f"Embree rtcIntersect1 on the same rays, 2 threads:  {b:.2f} Mrays/s")
    print(f"ratio: {a / b:.2f} (target >= 0.5), medians of {args.rounds} alternating rounds, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
