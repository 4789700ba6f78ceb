"""Parsing of `mobirt render --timings` output (the human-readable table) into numbers."""
import re

# Stage lines of print_timings() in src/app/main.cpp: "<label>   <ms> ...".
_STAGES = {
    "kd-tree build": "build",
    "primary rays": "rays_gen",
    "upload": "upload",
    "traversal passes": "traversal",
    "read-back": "read-back",
    "hit decoding": "decoding",
    "shading passes": "shading",
    "accumulate": "accumulate",
    "secondary rays": "secondary",
    "frame": "frame",
}


# The stage keys parse_timings() returns, in the order the table prints them.
STAGE_KEYS = list(_STAGES.values())


def parse_timings(text):
    """Returns {stage: ms, 'rays': n, 'shadow_rays': n, 'generations': [...]}"""
    out = {v: 0.0 for v in _STAGES.values()}
    out["rays"] = 0
    out["shadow_rays"] = 0
    out["generations"] = []
    in_generations = False
    for line in text.splitlines():
        if line.startswith("generation "):
            in_generations = True
            continue
        if in_generations:
            f = line.split()
            if len(f) == 6:
                out["generations"].append({"generation": int(f[0]), "rays": int(f[1]), "shadow_rays": int(f[2]),
                                           "traversal": float(f[3]), "mrays": float(f[4]), "shading": float(f[5])})
            continue
        for label, key in _STAGES.items():
            if line.startswith(label + " ") and re.match(r"^\s*[-\d.]+", line[len(label):]):
                out[key] = float(line[len(label):].split()[0])
                if key == "traversal":
                    m = re.search(r"\((\d+) rays \+ (\d+) shadow rays\)", line)
                    if m:
                        out["rays"], out["shadow_rays"] = int(m.group(1)), int(m.group(2))
                break
    return out
