#!/usr/bin/env python3
"""Parameter sweeps of `mobirt render`: per-pass times for each value of one setting at a time.

  tools/profile/sweep.py OUT.csv [--mobirt build/mobirt] [--repeat 3] [--params stack,bins,...]
                         [--scenes utah,toaster,...] [--budget SECONDS]

Each run is `mobirt render SCENE --timings-json F --repeat R --always-rebuild --primary trace
[the scene's options] [the swept option]` (the primaries traced, as in the paper's passes): one warm-up frame (shader compilation), then the stage-by-stage
median of R frames, the kd-tree rebuilt in every frame so that its build time is measured. One row
per run goes to OUT.csv: scene, parameter, value, and every stage in ms (build, primary rays,
upload, traversal pass, its read-back, hit decoding, shading pass, its read-back, accumulate,
secondary rays, frame), the rays and shadow rays traced and the traversal pass's Mrays/s.

Parameters (the defaults stay at mobirt's own for everything not swept):
  stack       --stack 0 1 2 4 8 16          short-stack entries (0 = pure kd-restart)
  bins        --bins 4 8 16 32 64           SAH bins of the kd-tree build
  size        --size 100x60 .. 800x480      resolution
  lights      1, 2, 4, 8 point lights       (0 = --no-shadows: no shadow rays at all)
  depth       --depth 0 1 2 3               bounces (scenes with mirrors or glass)
  threads     LP_NUM_THREADS 0 1 2 4        lavapipe's rasteriser threads (0 = in the caller)
  max_steps   --max-steps 256 .. 65535      the traversal loop's cap
Runs stop when --budget seconds have passed (the rows written so far stay).
"""
import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SHARED = os.environ.get("MOBIRT_SHARED_SCENES", os.path.join(ROOT, "..", "..", "shared", "scenes"))
if not os.path.isdir(SHARED):
    SHARED = os.path.join(ROOT, "..", "shared", "scenes")

# name: (file, options, has mirrors or glass, light positions for the lights sweep or None)
SCENES = {
    "utah": (os.path.join(SHARED, "utah-toasters", "Toasters004.obj"),
             ["--camera", "0,260,480:0,20,0:0,1,0:40", "--light", "point pos=150,500,300 intensity=300000",
              "--depth", "0"],
             False,
             ["150,500,300", "-200,400,300", "0,600,-200", "300,300,-300", "-300,500,-100", "100,700,100",
              "-100,300,500", "400,450,50"]),
    "toaster": (os.path.join(ROOT, "scenes", "toaster.gltf"), [], True, None),
    "marbles": (os.path.join(ROOT, "scenes", "marbles.gltf"), ["--size", "240x400"], True, None),
    "fish": (os.path.join(ROOT, "scenes", "fish.gltf"), [], True, None),
    "default": (os.path.join(ROOT, "scenes", "default.gltf"), [], True, None),
}

SWEEPS = {
    "stack": [["--stack", str(v)] for v in (0, 1, 2, 4, 8, 16)],
    "bins": [["--bins", str(v)] for v in (4, 8, 16, 32, 64)],
    "size": [["--size", v] for v in ("100x60", "200x120", "400x240", "800x480")],
    "lights": None,  # per scene, below
    "depth": [["--depth", str(v)] for v in (0, 1, 2, 3)],
    "threads": [("LP_NUM_THREADS", str(v)) for v in (0, 1, 2, 4)],
    "max_steps": [["--max-steps", str(v)] for v in (256, 1024, 2048, 8192, 65535)],
}

STAGES = ["build_ms", "rays_ms", "upload_ms", "trace_ms", "trace_readback_ms", "decode_ms", "shade_ms",
          "shade_readback_ms", "accumulate_ms", "secondary_ms", "frame_ms"]


def value_of(option):
    if isinstance(option, tuple):
        return option[1]
    if option and option[0] == "--light":
        return str(sum(1 for o in option if o == "--light"))
    return option[-1] if option else ""


def lights_sweep(positions):
    runs = [["--no-shadows"]]
    for n in (1, 2, 4, 8):
        option = []
        for p in positions[:n]:
            option += ["--light", f"point pos={p} intensity={300000 // n}"]
        runs.append(option)
    return runs


def render(mobirt, scene_file, options, env, repeat):
    with tempfile.TemporaryDirectory() as tmp:
        js = os.path.join(tmp, "t.json")
        cmd = [mobirt, "render", scene_file, "-o", os.path.join(tmp, "out.png"), "--timings-json", js,
               "--repeat", str(repeat), "--always-rebuild", "--primary", "trace"] + options
        out = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if out.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)}: {out.stderr.strip()}")
        with open(js) as f:
            return json.load(f)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out")
    parser.add_argument("--mobirt", default=os.path.join(ROOT, "build", "mobirt"))
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--params", default=",".join(SWEEPS))
    parser.add_argument("--scenes", default="utah,toaster")
    parser.add_argument("--budget", type=float, default=420.0, help="seconds; stops starting runs after it")
    args = parser.parse_args()
    start = time.time()
    rows = 0
    with open(args.out, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "parameter", "value", "width", "height", "lights", "rays", "shadow_rays",
                    "trace_mrays"] + STAGES)
        for scene in args.scenes.split(","):
            scene_file, base, bounces, light_positions = SCENES[scene]
            if not os.path.exists(scene_file):
                print(f"sweep: {scene_file} not found, {scene} skipped", file=sys.stderr)
                continue
            for param in args.params.split(","):
                if param == "depth" and not bounces:
                    continue
                if param == "lights":
                    if not light_positions:
                        continue
                    runs = lights_sweep(light_positions)
                    base_options = [o for i, o in enumerate(base) if not (o == "--light" or (i > 0 and base[i - 1] == "--light"))]
                else:
                    runs = SWEEPS[param]
                    base_options = base
                for option in runs:
                    if time.time() - start > args.budget:
                        print(f"sweep: time budget of {args.budget:.0f} s spent after {rows} runs", file=sys.stderr)
                        return
                    env = dict(os.environ)
                    options = list(base_options)
                    if isinstance(option, tuple):
                        env[option[0]] = option[1]
                    else:
                        # A later option replaces an earlier one of the same name (--depth, --size).
                        options += option
                    try:
                        j = render(args.mobirt, scene_file, options, env, args.repeat)
                    except RuntimeError as e:
                        print(f"sweep: {e}", file=sys.stderr)
                        continue
                    m = j["median"]
                    w.writerow([scene, param, value_of(option), j["width"], j["height"], j["lights"], m["rays"],
                                m["shadow_rays"], f"{m['trace_mrays']:.4f}"] + [f"{m[s]:.4f}" for s in STAGES])
                    f.flush()
                    rows += 1
                    print(f"{scene:8s} {param:9s} {value_of(option):8s} traversal {m['trace_ms']:8.2f} ms "
                          f"{m['trace_mrays']:5.2f} Mrays/s  frame {m['frame_ms']:8.2f} ms", flush=True)


if __name__ == "__main__":
    main()
