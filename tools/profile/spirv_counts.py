#!/usr/bin/env python3
"""Static SPIR-V instruction counts of the traversal and shading shaders, per specialisation.

  tools/profile/spirv_counts.py OUT.csv

Compiles glsl/trace.frag and glsl/shade.frag with glslangValidator (as the build does), then for
every variant freezes the specialization constants with spirv-opt (--set-spec-const-default-value
"ID:VALUE ..." --freeze-spec-const --fold-spec-const-op-composite; without the last, expressions of
constants such as STACK_DEPTH > 2 stay unfolded), optimises (-O, no loop unrolling: lavapipe does
not unroll our loops either), and counts with spirv-dis:
  instructions   every instruction inside a function (what the driver compiles)
  loops          OpLoopMerge (loops left; each runs at least once on llvmpipe)
  texel_fetches  OpImageFetch + OpImageSample* (calls of a texture function on lavapipe)
  module         every line of the module (declarations included)
Variants: trace: lights 0/1/4/8 (packing 24/8) and 16 (packing 16/16) x stack 0/4/16;
shade: lights 0/1/4/8/16 x textures 0/6/16. Spec ids: glsl/layout.h.
"""
import csv
import os
import subprocess
import sys
import tempfile

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
SPEC_LIGHTS, SPEC_STACK, SPEC_MAX_STEPS, SPEC_PACKING, SPEC_TEXTURES = 0, 1, 2, 3, 4


def compile_glsl(name, out):
    subprocess.run(["glslangValidator", "--quiet", "-V", "--target-env", "vulkan1.1", "-I" + os.path.join(ROOT, "glsl"),
                    "-o", out, os.path.join(ROOT, "glsl", name)], check=True)


def count(spv, spec, tmp):
    frozen = os.path.join(tmp, "frozen.spv")
    values = " ".join(f"{k}:{v}" for k, v in spec.items())
    subprocess.run(["spirv-opt", "--set-spec-const-default-value", values, "--freeze-spec-const",
                    "--fold-spec-const-op-composite", "-O", spv,
                    "-o", frozen], check=True)
    text = subprocess.run(["spirv-dis", "--no-header", "--raw-id", frozen], check=True, capture_output=True,
                          text=True).stdout.splitlines()
    in_function = False
    c = {"instructions": 0, "loops": 0, "texel_fetches": 0, "module": len(text)}
    for line in text:
        op = line.split("=")[-1].split()[0] if line.strip() else ""
        if op == "OpFunction":
            in_function = True
        if in_function and op not in ("OpLabel", "OpFunction", "OpFunctionEnd", "OpFunctionParameter"):
            c["instructions"] += 1
        if op == "OpFunctionEnd":
            in_function = False
        if op == "OpLoopMerge":
            c["loops"] += 1
        if op == "OpImageFetch" or op.startswith("OpImageSample"):
            c["texel_fetches"] += 1
    return c


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        trace, shade = os.path.join(tmp, "trace.spv"), os.path.join(tmp, "shade.spv")
        compile_glsl("trace.frag", trace)
        compile_glsl("shade.frag", shade)
        for lights in (0, 1, 4, 8, 16):
            for stack in (0, 4, 16):
                packing = 1 if lights > 8 else 0
                spec = {SPEC_LIGHTS: lights, SPEC_STACK: stack, SPEC_MAX_STEPS: 2048, SPEC_PACKING: packing}
                c = count(trace, spec, tmp)
                rows.append(["trace", lights, "", stack, "16/16" if packing else "24/8"] + [c[k] for k in
                            ("instructions", "loops", "texel_fetches", "module")])
            for textures in (0, 6, 16):
                c = count(shade, {SPEC_LIGHTS: lights, SPEC_TEXTURES: textures}, tmp)
                rows.append(["shade", lights, textures, "", ""] + [c[k] for k in
                            ("instructions", "loops", "texel_fetches", "module")])
    with open(sys.argv[1], "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["shader", "lights", "textures", "stack", "packing", "instructions", "loops", "texel_fetches",
                    "module"])
        w.writerows(rows)
    for r in rows:
        print(",".join(str(x) for x in r))


if __name__ == "__main__":
    main()
