#!/usr/bin/env python3
"""Summarizes a size/error sweep (tools/validate/size_error.sh output, JSON
lines): a markdown table of every point, each mode's Pareto front, and, for
every point of the 2d and 4d fronts, the error of the adaptive front at the
same size (log-log interpolation).

    python3 tools/validate/pareto.py sweep.jsonl
"""
import json
import math
import sys


def front(points):
    """Points not beaten in both size and error, by size."""
    pts = sorted(points, key=lambda p: (p["file_bytes"], p["achieved_error"]))
    out, best = [], math.inf
    for p in pts:
        if p["achieved_error"] < best:
            out.append(p)
            best = p["achieved_error"]
    return out


def error_at(front_pts, size):
    """Error of a front at `size` (log-log interpolation; None outside)."""
    for a, b in zip(front_pts, front_pts[1:]):
        if a["file_bytes"] <= size <= b["file_bytes"]:
            t = (math.log(size) - math.log(a["file_bytes"])) / (math.log(b["file_bytes"]) - math.log(a["file_bytes"]))
            return math.exp(math.log(a["achieved_error"]) * (1 - t) + math.log(b["achieved_error"]) * t)
    if front_pts and size >= front_pts[-1]["file_bytes"]:
        return front_pts[-1]["achieved_error"]
    return None


def main():
    rows = [json.loads(l) for l in open(sys.argv[1]) if l.startswith("{")]
    print("| mode | bits | target | bytes | ratio | error |\n|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['mode']} | {r['bits']} | {r['target']} | {r['file_bytes']} | {r['ratio']} | {r['achieved_error']:.5f} |")
    fronts = {m: front([r for r in rows if r["mode"] == m]) for m in ("2d", "4d", "adaptive")}
    print("\nPareto fronts (bytes → error):")
    for m, f in fronts.items():
        print(f"- {m}: " + ", ".join(f"{p['file_bytes']} → {p['achieved_error']:.4f}" for p in f))
    print("\n| size (bytes) | 2d error | 4d error | adaptive error |\n|---|---|---|---|")
    sizes = sorted({p["file_bytes"] for m in ("2d", "4d") for p in fronts[m]})
    worse = 0
    for s in sizes:
        e = {m: error_at(fronts[m], s) for m in fronts}
        fmt = lambda v: "—" if v is None else f"{v:.4f}"
        print(f"| {s} | {fmt(e['2d'])} | {fmt(e['4d'])} | {fmt(e['adaptive'])} |")
        others = [v for m, v in e.items() if m != "adaptive" and v is not None]
        if e["adaptive"] is not None and others and e["adaptive"] > max(others) * 1.001:
            worse += 1
    print(f"\nsizes where adaptive is worse than both others: {worse}")


if __name__ == "__main__":
    main()
