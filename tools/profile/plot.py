#!/usr/bin/env python3
"""PNG plots of tools/profile's CSV files (matplotlib, no display needed).

  tools/profile/plot.py DIR

Reads what exists of DIR/sweep.csv, DIR/spirv.csv and DIR/simd_*.csv and writes:
  sweep_PARAM.png   per swept parameter: per-pass times (traversal, shading, read-backs, decoding,
                    build, frame) against the value, one panel per scene, and the traversal pass's
                    Mrays/s on a second axis
  spirv.png         static SPIR-V instructions per shader variant
  simd.png          llvmpipe lane occupancy of the traversal loops per scene and ray generation
"""
import csv
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

STAGES = [("trace_ms", "traversal pass"), ("shade_ms", "shading pass"), ("decode_ms", "hit decoding"),
          ("build_ms", "kd-tree build"), ("read_ms", "read-backs"), ("frame_ms", "frame")]


def read(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def plot_sweeps(rows, out_dir):
    by_param = defaultdict(list)
    for r in rows:
        r["read_ms"] = str(float(r["trace_readback_ms"]) + float(r["shade_readback_ms"]))
        by_param[r["parameter"]].append(r)
    written = []
    for param, prows in by_param.items():
        scenes = sorted({r["scene"] for r in prows}, key=[r["scene"] for r in prows].index)
        fig, axes = plt.subplots(1, len(scenes), figsize=(6 * len(scenes), 4.2), squeeze=False)
        for ax, scene in zip(axes[0], scenes):
            srows = [r for r in prows if r["scene"] == scene]
            labels = [r["value"] for r in srows]
            xs = range(len(srows))
            for key, label in STAGES:
                ax.plot(xs, [float(r[key]) for r in srows], marker="o", label=label)
            ax.set_xticks(list(xs))
            ax.set_xticklabels(labels)
            ax.set_xlabel(param)
            ax.set_ylabel("ms (median frame)")
            ax.set_yscale("log")
            ax.set_title(scene)
            ax.grid(True, which="both", alpha=0.3)
            ax2 = ax.twinx()
            ax2.plot(xs, [float(r["trace_mrays"]) for r in srows], color="black", linestyle="--", marker="x",
                     label="traversal Mrays/s")
            ax2.set_ylabel("traversal Mrays/s")
            ax2.set_ylim(bottom=0)
            if ax is axes[0][0]:
                h1, l1 = ax.get_legend_handles_labels()
                h2, l2 = ax2.get_legend_handles_labels()
                ax.legend(h1 + h2, l1 + l2, fontsize=7, loc="upper left")
        fig.suptitle(f"mobirt on lavapipe: per-pass time against {param}")
        fig.tight_layout()
        path = os.path.join(out_dir, f"sweep_{param}.png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def grouped_bars(ax, rows, group_key, series_key, series_label, title):
    """Bars of rows' instruction counts: one group per value of group_key (lights), one bar per
    value of series_key (stack depth or textures)."""
    groups = sorted({r[group_key] for r in rows}, key=int)
    series = sorted({r[series_key] for r in rows}, key=int)
    width = 0.8 / len(series)
    for i, s in enumerate(series):
        vals = [next(int(r["instructions"]) for r in rows if r[series_key] == s and r[group_key] == g) for g in groups]
        ax.bar([x + i * width for x in range(len(groups))], vals, width, label=series_label(s))
    ax.set_xticks([x + 0.4 - width / 2 for x in range(len(groups))])
    ax.set_xticklabels([f"{g} lights" for g in groups])
    ax.set_title(title)
    ax.set_ylabel("SPIR-V instructions (spirv-opt -O)")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)


def plot_spirv(rows, out_dir):
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    grouped_bars(axes[0], [r for r in rows if r["shader"] == "trace"], "lights", "stack", lambda s: f"stack {s}",
                 "trace.frag: instructions after specialisation")
    grouped_bars(axes[1], [r for r in rows if r["shader"] == "shade"], "lights", "textures",
                 lambda s: f"{s} textures", "shade.frag: instructions after specialisation")
    fig.tight_layout()
    path = os.path.join(out_dir, "spirv.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path]


def plot_simd(files, out_dir):
    fig, ax = plt.subplots(figsize=(8, 4.2))
    labels, node, leaf = [], [], []
    for name, rows in files:
        for r in rows:
            labels.append(f"{name}\ngen {r['generation']}")
            node.append(float(r["node_occupancy"]))
            leaf.append(float(r["leaf_occupancy"]))
    xs = range(len(labels))
    ax.bar([x - 0.2 for x in xs], node, 0.4, label="node loop")
    ax.bar([x + 0.2 for x in xs], leaf, 0.4, label="triangle loop")
    ax.set_xticks(list(xs))
    ax.set_xticklabels(labels, fontsize=7)
    ax.set_ylim(0, 1)
    ax.set_ylabel("lanes doing useful work (of 8)")
    ax.set_title("llvmpipe SIMD occupancy of the traversal loops (4x2 fragment groups)")
    ax.legend()
    ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    path = os.path.join(out_dir, "simd.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return [path]


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    d = sys.argv[1]
    written = []
    if os.path.exists(os.path.join(d, "sweep.csv")):
        written += plot_sweeps(read(os.path.join(d, "sweep.csv")), d)
    if os.path.exists(os.path.join(d, "spirv.csv")):
        written += plot_spirv(read(os.path.join(d, "spirv.csv")), d)
    simd = sorted(f for f in os.listdir(d) if f.startswith("simd_") and f.endswith(".csv"))
    if simd:
        written += plot_simd([(f[5:-4], read(os.path.join(d, f))) for f in simd], d)
    for w in written:
        print(w)


if __name__ == "__main__":
    main()
