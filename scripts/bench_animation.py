"""What the add-on costs an animation (addon/lab/bench_animation.py): the lamps' hand-over per
frame against the frame's render time, and the HDRI sun search's time and memory.

    python scripts/bench_animation.py [--frames 100] [--samples 4] [--preset rough_gold_lee]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from addon.lab import bench_animation  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--preset", default="rough_gold_lee")
    parser.add_argument("--hdri", type=int, nargs="+", default=[4096, 8192],
                        help="HDRI widths to measure the sun search on (the first lights the animation)")
    args = parser.parse_args(argv)
    r = bench_animation.run(frames=args.frames, samples=args.samples, preset=args.preset,
                            hdri_widths=args.hdri)
    print(f"\n{r['frames']} frames of {r['size'][0]}x{r['size'][1]} px at {r['samples']} spp, "
          f"preset {r['preset']}, a turning sun, a moving area lamp, a {args.hdri[0]}-px HDRI")
    print(f"  frame without hand-over (frame 1's lamps kept): {r['frame']:.3f} s")
    print(f"  hand-over, measured inside the handler:        {r['handover_per_frame']:.3f} s/frame")
    print(f"  prediction withdrawn after the job:            {sum(r['live']['withdraw']):.3f} s")
    print(f"  hand-over, total difference of the two runs:   {r['overhead_per_frame']:.3f} s/frame "
          f"= {100 * r['overhead_share']:.1f}% of a frame")
    w, h, spp, seconds = r["typical"]
    print(f"  one {w}x{h} frame at {spp} spp of the same scene: {seconds:.1f} s; the hand-over "
          f"is {100 * r['typical_share']:.1f}% of it")
    for s in r["spot_search"]:
        print(f"  HDRI {s['size'][0]}x{s['size'][1]} ({s['image_mb']:.0f} MB as RGBA float), {s['route']}: "
              f"sun search {s['seconds']:.2f} s, numpy allocates {s['peak_mb']:.0f} MB = "
              f"{100 * s['share']:.0f}% of it; resident memory +{s['rss_mb']:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
