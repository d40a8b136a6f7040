#!/usr/bin/env python3
"""Tables for docs/results/pca.md from the outputs of pca_figures.sh:
PCA rank/size at each target, frame time and relit error at each K, and
the crossover against the adaptive file at equal frame time.

    python3 tools/validate/pca_table.py OUTDIR
"""
import json, re, sys, pathlib

out = pathlib.Path(sys.argv[1])
rows = [json.loads(l) for l in open(out / "relight.jsonl") if l.strip()]
raw = (out / "scene.raw").stat().st_size

def log(name):
    t = (out / name).read_text()
    m = re.search(r"wrote .*?: (\d+) bytes .*?(?:pca rank (\d+), )?(\d+) bits.*?relative L2 error ([0-9.]+)", t)
    # The command's own time (the wall time in the log includes waiting
    # for the shared lock).
    secs = re.search(r"wrote [^\n]*?, ([0-9.]+) s", t)
    return m, secs.group(1) if secs else "?"

print(f"raw store: {raw/1e9:.2f} GB\n")
print("| file | rank K | bits | size | ratio | matrix error | compress time |\n|---|---|---|---|---|---|---|")
for name in ["pca-0.01", "pca-0.03", "pca-r256", "adaptive-0.01"]:
    p = out / f"{name}.log"
    if not p.exists():
        continue
    m, secs = log(f"{name}.log")
    if not m:
        print(f"| {name} | (failed: see log) |"); continue
    size = int(m.group(1))
    print(f"| {name} | {m.group(2) or '–'} | {m.group(3)} | {size/1e6:.1f} MB | {raw/size:.0f}× | {100*float(m.group(4)):.3f} % | {secs} s |")

def series(suffix):
    return sorted([r for r in rows if str(r["file"]).endswith(suffix)], key=lambda r: r["lights"])

print("\nThe rank-256 file (16 bits), first K eigen-transports:\n")
print("| K | frame ms | projection ms | dot products ms | coefficients GB/s | relit error vs T·L |\n|---|---|---|---|---|---|")
for r in series("pca-r256.ltm"):
    k = r["lights"]
    gbs = r["nonzeros"] * 4 / (r["multiply_ms"] * 1e-3) / 1e9
    print(f"| {k} | {r['frame_ms']:.3f} | {r['light_transform_ms']:.3f} | {r['multiply_ms']:.3f} | {gbs:.1f} | {100*r['relative_error']:.3f} % |")

pca = series("pca-0.01.ltm") or series("pca-r256.ltm")
ada = series("adaptive-0.01.ltm")
print("\nAt 1 % matrix error: the pca file over its first N terms and the adaptive file over N wavelet lights (transport weighting):\n")
print("| file | N | frame ms | relit error |\n|---|---|---|---|")
for r in pca + ada:
    print(f"| {pathlib.Path(r['file']).stem} | {r['lights']} | {r['frame_ms']:.3f} | {100*r['relative_error']:.3f} % |")

# Crossover: for each adaptive point, the pca error at the same frame time
# (interpolated in log time over the pca series); the first N where the
# adaptive error is lower.
import math
def pca_err_at(t):
    pts = [(r["frame_ms"], r["relative_error"]) for r in pca]
    pts.sort()
    best = None
    for ms, e in pts:  # the best pca error reachable within time t
        if ms <= t:
            best = e if best is None else min(best, e)
    return best
print()
cross = None
for r in ada:
    pe = pca_err_at(r["frame_ms"])
    if pe is not None and r["relative_error"] < pe:
        cross = r; break
if cross:
    print(f"Crossover: adaptive at N = {cross['lights']} ({cross['frame_ms']:.3f} ms, relit error {100*cross['relative_error']:.3f} %) beats the best pca setting within the same frame time ({100*pca_err_at(cross['frame_ms']):.3f} %).")
else:
    fastest = min(ada, key=lambda r: r["frame_ms"]) if ada else None
    print("No crossover: at no swept N does the adaptive file beat the best pca setting of equal or lower frame time.")
