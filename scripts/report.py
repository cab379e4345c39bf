"""`make report`: error against render time, sampler weights, the reference's cost and numerical
stability of every Microfacet Lab model, and the Lee 2018 V-groove measurements (furnace, cost
per sample against Cook-Torrance, closed form against the tracer, moment rules), written to
report/ (report.md, PNG plots, results.json). See the package addon/lab/report/ (one module per
section; its __init__ lists them).

    python scripts/report.py            # full (over an hour on 2 cores); refreshes docs/figures
    python scripts/report.py --quick    # about 5 minutes
    python scripts/report.py --smoke    # a minute: 2 sample counts, one tiny grid (no Stochastic
                                        # row beside its Native + Residual twin), one environment
    python scripts/report.py --quick --sections convergence --rows "Heitz 2016" --envs sun,point
"""
import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_true", help="fewer samples, smaller grids")
    group.add_argument("--smoke", action="store_true", help="a tiny run for the tests")
    parser.add_argument("--out", default=str(ROOT / "report"), help="output folder")
    parser.add_argument("--figures", default=None,
                        help="copy the README figures here (default: docs/figures on a full run)")
    from addon.lab.report.config import SECTIONS

    parser.add_argument("--sections", default=",".join(SECTIONS),
                        help="comma-separated subset of " + ",".join(SECTIONS))
    parser.add_argument("--rows", default="",
                        help="comma-separated words: only the convergence rows whose variant "
                             "contains one (e.g. 'Heitz 2016')")
    parser.add_argument("--envs", default="",
                        help="comma-separated subset of the mode's environments (e.g. sun,point)")
    args = parser.parse_args(argv)
    mode = "smoke" if args.smoke else "quick" if args.quick else "full"
    figures = args.figures or (str(ROOT / "docs" / "figures") if mode == "full" else None)

    from addon.lab import report

    report.run(mode, args.out, figures, sections=tuple(args.sections.split(",")),
               rows=tuple(w for w in args.rows.split(",") if w),
               envs=tuple(e for e in args.envs.split(",") if e))


if __name__ == "__main__":
    main()
