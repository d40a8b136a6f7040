"""Frame time of `Relighter.relight` from Python against `ltm relight`'s.

Both relight the same file under the same map at the same N; each reports
the median of --frames frames. The CLI's `frame_ms` times frames that each
transform their lighting anew (and `same_light_frame_ms` frames that reuse
it); from Python, a frame alternates between the map's cubemap and a copy
one ulp apart in one texel (so each frame transforms its lighting, and
selects and multiplies the same lights), and the same-light frames pass one
cubemap each time. Python's times are wall clock around the call: reading
the array, releasing the interpreter, the frame, and the image handed back.

    python python/bench/relight_speed.py --ltm-bin target/release/ltm

Without --file it bakes assets/scenes/default.toml at --size and
--face-res and compresses it (adaptive, max_error 0.01) into --work.
"""

import argparse
import json
import pathlib
import statistics
import subprocess
import time

import numpy as np

import ltm

ROOT = pathlib.Path(__file__).resolve().parents[2]


def make_file(args):
    work = pathlib.Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    path = work / f"bench-{args.size}-{args.face_res}.ltm"
    if not path.exists():
        raw = work / f"bench-{args.size}-{args.face_res}.raw"
        if not raw.exists():
            ltm.bake(ROOT / "assets/scenes/default.toml", raw, width=args.size,
                     height=args.size, face_res=args.face_res)
        ltm.compress(raw, path, max_error=0.01)
    return path


def cli_frames(args, path):
    out = pathlib.Path(args.work) / "bench-cli.exr"
    line = subprocess.run(
        [args.ltm_bin, "relight", str(path), "--env", str(args.env), "--terms",
         str(args.terms), "--frames", str(args.frames), "--json", "-o", str(out)],
        check=True, capture_output=True, text=True,
    ).stdout
    return json.loads(line)


def python_frames(args, path):
    r = ltm.open(path).relighter()
    a = r.cubemap(args.env)
    b = a.copy()
    b[0, 0] = np.nextafter(b[0, 0], np.float32(np.inf))
    r.relight(a, terms=args.terms)  # decodes the columns it uses, as the CLI's first frame
    new, same = [], []
    for k in range(args.frames):
        light = b if k % 2 == 0 else a
        t = time.perf_counter()
        r.relight(light, terms=args.terms)
        new.append(time.perf_counter() - t)
    for _ in range(args.frames):
        t = time.perf_counter()
        r.relight(a, terms=args.terms)
        same.append(time.perf_counter() - t)
    path_times = []
    for _ in range(args.frames):
        t = time.perf_counter()
        r.relight(args.env, terms=args.terms)
        path_times.append(time.perf_counter() - t)
    ms = lambda v: statistics.median(v) * 1e3
    return ms(new), ms(same), ms(path_times)


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--ltm-bin", default=str(ROOT / "target/release/ltm"))
    p.add_argument("--file", help="an .ltm file (default: bake and compress one)")
    p.add_argument("--env", default=str(ROOT / "assets/envmaps/interior.exr"))
    p.add_argument("--terms", type=int, default=200)
    p.add_argument("--frames", type=int, default=21)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--face-res", type=int, default=16)
    p.add_argument("--work", default=str(ROOT / "target/python-bench"))
    args = p.parse_args()
    path = pathlib.Path(args.file) if args.file else make_file(args)
    f = ltm.open(path)
    print(f"{path}: {f.mode}, {f.dims['width']}x{f.dims['height']}, "
          f"{f.dims['lights']} lights, {f.size} bytes; N = {args.terms}, "
          f"median of {args.frames} frames, {args.rounds} rounds")
    # Alternate the two, round after round, against a busy machine's drift;
    # each figure is the median of the rounds' medians.
    rounds = [(cli_frames(args, path), python_frames(args, path)) for _ in range(args.rounds)]
    mid = statistics.median
    cli = {k: mid(c[k] for c, _ in rounds) for k in ("frame_ms", "same_light_frame_ms")}
    new, same, by_path = (mid(p[i] for _, p in rounds) for i in range(3))
    print("rounds (CLI new, Python new, CLI same, Python same, ms): " + "; ".join(
        f"{c['frame_ms']:.3f} {p[0]:.3f} {c['same_light_frame_ms']:.3f} {p[1]:.3f}"
        for c, p in rounds))
    print(f"new lighting:  CLI {cli['frame_ms']:.3f} ms, Python {new:.3f} ms "
          f"({100 * (new / cli['frame_ms'] - 1):+.1f} %)")
    print(f"same lighting: CLI {cli['same_light_frame_ms']:.3f} ms, Python {same:.3f} ms "
          f"({100 * (same / cli['same_light_frame_ms'] - 1):+.1f} %)")
    ratio = lambda k, i: mid(p[i] / c[k] for c, p in rounds)
    print(f"median over rounds of Python / CLI (same round): new lighting "
          f"{ratio('frame_ms', 0):.3f}, same lighting {ratio('same_light_frame_ms', 1):.3f}")
    print(f"Python with the map's path (resampled to the cubemap each frame): {by_path:.3f} ms")


if __name__ == "__main__":
    main()
