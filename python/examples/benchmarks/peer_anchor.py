"""A whole calibration beside a peer's, for ``cargo xtask bench`` (issue 61): SEPIA's ball drop
without discrepancy, through surmise 1.0's ``directbayes`` calibrator and through bamudi, with the
same simulator, prior U(0.05, 0.25) and known observation sd 0.01 s, i.e. the same likelihood
(``peers.surmise_ball_drop``; docs/results/peers.md says why this problem and what each side
computes).

    pip install ./python surmise
    python python/examples/benchmarks/peer_anchor.py [--runs 3]

Runs the pair ``--runs`` times (each with the same seeds, so the posteriors repeat and only the
wall times vary) and prints, last, one ``anchor`` line of ``key=value`` pairs that ``cargo xtask
bench`` reads: the median wall times (s) and the posteriors' means and sds of C.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import peers  # noqa: E402  (the example's own module, next to this script)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=3, help="repetitions; the wall times are their medians")
    args = ap.parse_args(argv)
    if args.runs < 1:
        ap.error("--runs must be at least 1")
    runs = [peers.surmise_ball_drop() for _ in range(args.runs)]
    last = runs[-1]
    out = {
        "peer_s": statistics.median(r["surmise_s"] for r in runs),
        "ours_s": statistics.median(r["ours_s"] for r in runs),
        "peer_mean": last["surmise"][0],
        "peer_sd": last["surmise"][1],
        "ours_mean": last["ours"][0],
        "ours_sd": last["ours"][1],
        "runs": args.runs,
    }
    print("anchor " + " ".join(f"{k}={v:.6g}" for k, v in out.items()))
    return out


if __name__ == "__main__":
    main()
