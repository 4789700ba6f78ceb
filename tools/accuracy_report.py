#!/usr/bin/env python3
"""The accuracy sweep's report: a Markdown table per scene and a Pareto plot per scene.

    tools/accuracy_report.py OUT/accuracy.csv OUT [--command TEXT] [--device TEXT]

Reads the rows `mobirt accuracy --csv` appends (one per setting) and writes OUT/accuracy.md and,
when matplotlib is importable, OUT/pareto_SCENE.png: frame time against PSNR and against the
primary-hit mismatch, the settings on the Pareto front (no other setting is both faster and more
accurate) joined by a line. tools/accuracy_sweep.sh runs it. The time compared is the fastest of
the timed frames (frame_min_ms): other work on the machine only ever adds time. Rows repeated by
several rounds of the sweep (same scene and label) are merged: the fastest frame over the rounds,
the median of their medians (the error columns are deterministic: the first round's).
"""
import argparse
import collections
import csv
import datetime
import os
import statistics
import sys


def pareto(rows, better):
    """The rows no other row beats in both frame time and `better` (larger is better)."""
    front, best = [], None
    for r in sorted(rows, key=lambda r: (r["frame_min_ms"], -better(r))):
        if best is None or better(r) > best:
            front.append(r)
            best = better(r)
    return front


def load(path):
    rounds = collections.OrderedDict()  # (scene, label) -> rows of every round
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            for key in ("frame_ms", "frame_min_ms", "psnr_db", "max_error", "share_over_2", "hit_mismatch",
                        "shadow_mismatch"):
                r[key] = float(r[key])
            rounds.setdefault((r["scene"], r["label"]), []).append(r)
    scenes = collections.OrderedDict()
    for (scene, _), rows in rounds.items():
        merged = dict(rows[0])
        merged["frame_min_ms"] = min(r["frame_min_ms"] for r in rows)
        merged["frame_ms"] = statistics.median(r["frame_ms"] for r in rows)
        merged["rounds"] = len(rows)
        scenes.setdefault(scene, []).append(merged)
    return scenes


def write_markdown(scenes, out, command, device):
    lines = []
    if command:
        date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d")
        lines += [f"Command: `{command}` ({date}{', ' + device if device else ''})", ""]
    rounds = max(r["rounds"] for rows in scenes.values() for r in rows)
    over = f" over {rounds} rounds" if rounds > 1 else ""
    lines += [f"frame ms: the median and the fastest of the timed frames{over}; Pareto: on the front of the "
              "fastest frame time against PSNR (no other setting is both faster and more accurate).", ""]
    for scene, rows in scenes.items():
        front = {id(r) for r in pareto(rows, lambda r: r["psnr_db"])}
        lines += [f"### {scene} ({rows[0]['size']})", "",
                  "| setting | frame ms (median, fastest) | PSNR dB | max error | > 2/255 | hit mismatch | shadow mismatch | Pareto |",
                  "|---|---:|---:|---:|---:|---:|---:|:---:|"]
        for r in rows:
            lines.append(f"| {r['label']} | {r['frame_ms']:.1f}, {r['frame_min_ms']:.1f} | {r['psnr_db']:.2f} | {255 * r['max_error']:.1f}/255 "
                         f"| {100 * r['share_over_2']:.3f}% | {100 * r['hit_mismatch']:.3f}% "
                         f"| {100 * r['shadow_mismatch']:.3f}% | {'yes' if id(r) in front else ''} |")
        lines.append("")
    with open(os.path.join(out, "accuracy.md"), "w") as f:
        f.write("\n".join(lines))
    return "\n".join(lines)


def plot(scenes, out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    for scene, rows in scenes.items():
        fig, axes = plt.subplots(1, 2, figsize=(12, 5))
        panels = [("psnr_db", "PSNR against the reference (dB, higher is better)", lambda r: r["psnr_db"], False),
                  ("hit_mismatch", "primary rays hitting another triangle than the reference (%)",
                   lambda r: -r["hit_mismatch"], True)]
        defaults = next((r for r in rows if r["label"] == "defaults"), rows[0])
        for ax, (key, label, better, percent) in zip(axes, panels):
            value = (lambda r: 100 * r[key]) if percent else (lambda r: r[key])
            front = pareto(rows, better)
            ax.plot([r["frame_min_ms"] for r in front], [value(r) for r in front], "-", color="0.6", lw=1,
                    zorder=1, label="Pareto front")
            on_front = {id(r) for r in front}
            quiet = labelled = 0
            for r in rows:
                mark = id(r) in on_front
                ax.scatter(r["frame_min_ms"], value(r), s=36 if mark else 18, zorder=2,
                           color="tab:red" if mark else "tab:blue", edgecolors="black" if mark else "none")
                # Labels for the front, the defaults and the settings whose error differs from the
                # defaults'; the others (same error, other time) are counted in the legend.
                same = abs(value(r) - value(defaults)) <= (0.2 * abs(value(defaults)) if percent else 0.5)
                if mark or r is defaults or not same:
                    # Alternately above and below the point, so that neighbours' labels do not overlap.
                    ax.annotate(r["label"], (r["frame_min_ms"], value(r)), fontsize=6,
                                xytext=(3, 2 if labelled % 2 == 0 else -8), textcoords="offset points")
                    labelled += 1
                else:
                    quiet += 1
            ax.scatter([], [], s=18, color="tab:blue",
                       label=f"{quiet} unlabelled: the defaults' error, another time (see the table)")
            ax.set_xscale("log")
            ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
            ax.xaxis.set_minor_locator(matplotlib.ticker.LogLocator(subs=(2.0, 3.0, 5.0)))
            ax.xaxis.set_minor_formatter(matplotlib.ticker.FormatStrFormatter("%.0f"))
            ax.tick_params(axis="x", which="minor", labelsize=6)
            if percent:
                ax.set_yscale("symlog", linthresh=0.001)
                ax.set_ylim(bottom=0.0)
            ax.set_xlabel("frame time (ms, fastest of the timed frames, log scale)")
            ax.set_ylabel(label)
            ax.grid(True, which="both", lw=0.3)
            ax.legend(loc="best", fontsize=7)
        fig.suptitle(f"{scene} ({rows[0]['size']}): speed against accuracy, one knob at a time from the defaults")
        fig.tight_layout()
        name = os.path.splitext(os.path.basename(scene))[0]
        fig.savefig(os.path.join(out, f"pareto_{name}.png"), dpi=110)
        plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    parser.add_argument("out")
    parser.add_argument("--command", default="")
    parser.add_argument("--device", default="")
    args = parser.parse_args()
    scenes = load(args.csv)
    os.makedirs(args.out, exist_ok=True)
    print(write_markdown(scenes, args.out, args.command, args.device))
    try:
        plot(scenes, args.out)
        print(f"sweep: Pareto plots in {args.out}/pareto_*.png", file=sys.stderr)
    except ImportError:
        print("sweep: python3 cannot import matplotlib: no Pareto plot (the CSV has the numbers)", file=sys.stderr)


if __name__ == "__main__":
    main()
