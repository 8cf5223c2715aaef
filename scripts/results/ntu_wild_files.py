"""NTU-format files "from the wild": rewrite clean files like an independent generator, and score body 0.

    python scripts/results/ntu_wild_files.py write --src data/ntu20 --out data/ntu20_wild [--seed 0]
    python scripts/results/ntu_wild_files.py score --cache data/ntu20_wild_cache --manifest data/ntu20_wild/wild_manifest.json

``write`` rewrites every ``.skeleton`` file under ``--src`` with frames without bodies, a flickering
spurious body (listed first in about half of the files) and CRLF line ends
(:mod:`mocapkit.datasets.synthetic.ntu_wild`), and writes ``wild_manifest.json`` (the real body IDs
of each sample). ``score`` reads a prepared cache's ``report.json`` and prints how often body 0 is a
real person.
"""

from __future__ import annotations

import argparse
import json

from mocapkit.datasets.synthetic.ntu_wild import MANIFEST, body0_correct, wild_copy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    write = sub.add_parser("write", help="rewrite a folder of .skeleton files")
    write.add_argument("--src", required=True, help="folder of clean .skeleton files (e.g. mocapkit synth ntu)")
    write.add_argument("--out", required=True, help="folder for the rewritten files and " + MANIFEST)
    write.add_argument("--seed", type=int, default=0)
    write.add_argument("--empty-frame-prob", type=float, default=0.05, help="fraction of frames without bodies")
    write.add_argument("--flicker-prob", type=float, default=1.0, help="fraction of files with a flickering body")
    score = sub.add_parser("score", help="how often body 0 of a prepared cache is a real person")
    score.add_argument("--cache", required=True, help="cache folder written by mocapkit prepare ntu")
    score.add_argument("--manifest", required=True, help=MANIFEST + " written by the write command")
    args = parser.parse_args()
    if args.command == "write":
        manifest = wild_copy(
            args.src, args.out, seed=args.seed, empty_frame_prob=args.empty_frame_prob, flicker_prob=args.flicker_prob
        )
        flickers = sum(info["flicker_body_id"] is not None for info in manifest.values())
        first = sum(info["flicker_first"] for info in manifest.values())
        print(
            f"wrote {len(manifest)} files to {args.out}: {flickers} with a flickering body "
            f"({first} listed first), {sum(i['empty_frames'] for i in manifest.values())} frames without bodies"
        )
    else:
        result = body0_correct(f"{args.cache}/report.json", args.manifest)
        print(json.dumps({k: v for k, v in result.items() if k != "wrong"}, indent=1))
        if result["wrong"]:
            print("body 0 not a real person in, e.g.:", ", ".join(result["wrong"][:10]))


if __name__ == "__main__":
    main()
