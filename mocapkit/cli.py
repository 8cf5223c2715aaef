"""The ``mocapkit`` command line.

    mocapkit synth ntu --out DIR [--classes N] [--subjects S] [--seed K] [--set KEY=VALUE ...]
    mocapkit synth hdm05 --out DIR [--classes NAME ...] [--actors bd bk ...] [--seed K]
    mocapkit synth casia-b --out DIR [--subjects S] [--frames F] [--size H] [--seed K] [--workers N]
    mocapkit synth depth MOCAP [MOCAP ...] --out DIR [--camera kinect_v1|azure_kinect|FILE.yaml]
                         [--noise kinect_v1|azure_kinect|none] [--format npz|png] [--seed K] [--fps F]
                         [--max-frames N] [--skip-bad]      (depth video of mocap, Lou 2012 ch. 3)
    mocapkit render FILE --out anim.gif [--strip]
    mocapkit prepare ntu --src DIR --out DIR [--workers N] [--skip-bad] [--missing-list FILE] [--min-body-frames N]
    mocapkit prepare casia-b --src DIR --out DIR [--size 64x44|124x124] [--per cycle|sequence] [--no-period ...]
    mocapkit pyskl export --cache DIR --out FILE.pkl [--splits ntu60|ntu120]     (pyskl / MMAction2 annotations)
    mocapkit pyskl import --pkl FILE.pkl --out DIR [--skip-bad] [--max-bodies N] [--classes FILE]
    mocapkit train [experiment=NAME] data.root=CACHE [Hydra overrides ...]      (-m: a sweep; resume=RUN/last.ckpt)
    mocapkit train --cfg job [overrides ...]      (print the composed config; --help: Hydra's help, the config groups)
    mocapkit eval ckpt_path=RUN/best.ckpt [overrides ...]
    mocapkit export ckpt_path=RUN/best.ckpt [out=FILE] [overrides ...]
    mocapkit predict --onnx FILE MOTION_FILE [MOTION_FILE ...]
    mocapkit compare NAME [overrides ...]                 (configs/compare/NAME.yaml: methods × protocols × seeds)
    mocapkit gait-report --data GEI_CACHE --out DIR [--protocols ...] [overrides ...]   (= compare gait)
    mocapkit refine IN OUT --method NAME [--set KEY=VALUE ...] [--train PATH ...] [--repair-outliers]
                    [--screen-outliers [METRES]]
    mocapkit refine IN OUT --method RUN/best.ckpt | --onnx FILE [--set KEY=VALUE ...] [--repair-outliers]
                    [--screen-outliers [METRES]]
    mocapkit index --src DIR --out INDEX [--method NAME] [--set KEY=VALUE ...] [--ckpt PATH] [--skip-bad]
                   [--workers N]
    mocapkit index --src DIR --out INDEX --add [--skip-bad] [--workers N]   (append without rebuilding)
    mocapkit search --index INDEX QUERY [QUERY ...] [-k K] [--json] [--within]
    mocapkit synthesize INPUT [INPUT ...] --out DIR [--type SUBSTRING] [--variants N] [--frames F] [--seed S]
                        [--window SECONDS] [--method NAME] [--no-footskate] [--set KEY=VALUE ...]
                        [--format amc|bvh]                                      (Zhou 2014 ch. 4)
    mocapkit kinect-fix train --mocap PATH [PATH ...] --out MODEL [--method NAME] [--noise PRESET]
                              [--set KEY=VALUE ...]
                        [--skip-bad]
    mocapkit kinect-fix export --model MODEL.pt --out MODEL.onnx                 (a learned corrector as ONNX)
    mocapkit kinect-fix apply INPUT [INPUT ...] --model MODEL --out DIR [--set KEY=VALUE ...] [--plot N]
                        [--skip-bad]                                            (Zhou 2014 ch. 5)
    mocapkit depth-track DEPTH [DEPTH ...] --out DIR [--prior MOCAP ...] [--method NAME] [--set KEY=VALUE ...]
                         [--camera PRESET|FILE.yaml] [--fps F] [--performer MOCAP_FILE] [--start sensor|standing]
                         [--skeleton sensor|template] [--format c3d|bvh] [--pictures N] [--skip-bad]
                                                          (full-body tracking from depth video, Lou 2012 ch. 3)

    mocapkit methods [TASK]                     (the method registry: task, name, learned, description)

--method NAME is a name of the method registry (configs/<task>/method/NAME.yaml, ``mocapkit methods``); --set
KEY=VALUE is a Hydra override of that method's parameters (null, true, 0.1, "[a,b]", "{k: v}").

Errors are one line (``mocapkit: error: ...``, exit code 2); ``mocapkit --debug COMMAND ...`` (or
``MOCAPKIT_DEBUG=1``) shows the traceback instead.
Heavy libraries are imported inside each command, so ``predict`` runs with
onnxruntime and numpy alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys


def cmd_synth_ntu(args: argparse.Namespace) -> None:
    from mocapkit.datasets.synthetic.ntu import NTUSynthConfig, synthesize_ntu
    from mocapkit.train.registry import override_values

    fields = sorted(f.name for f in dataclasses.fields(NTUSynthConfig))
    values = {
        key: tuple(value) if isinstance(value, list) else value  # Hydra's grammar: --set "setups=[1,2]"
        for key, value in override_values(args.set or [], fields, "NTUSynthConfig").items()
    }
    for option, name in (
        ("classes", "num_classes"),
        ("subjects", "num_subjects"),
        ("seed", "seed"),
        ("setups", "setups"),
        ("cameras", "cameras"),
        ("replications", "replications"),
    ):
        value = getattr(args, option)
        if value is not None:
            values[name] = tuple(value) if isinstance(value, list) else value
    config = NTUSynthConfig(**values)
    files = synthesize_ntu(args.out, config, workers=args.workers, progress=not args.quiet)
    print(f"[mocapkit] wrote {len(files)} .skeleton files to {args.out}")


def cmd_synth_hdm05(args: argparse.Namespace) -> None:
    from mocapkit.datasets.synthetic.hdm05 import HDM05SynthConfig, synthesize_hdm05

    values = {}
    if args.classes:
        values["classes"] = tuple(args.classes)
    if args.actors:
        values["actors"] = tuple(args.actors)
    for name in ("seed", "clips_per_actor"):
        if getattr(args, name) is not None:
            values[name] = getattr(args, name)
    files = synthesize_hdm05(args.out, HDM05SynthConfig(**values), progress=not args.quiet)
    print(f"[mocapkit] wrote {len(files)} .amc clips (and one .asf per actor) to {args.out}")


def cmd_synth_casia_b(args: argparse.Namespace) -> None:
    from mocapkit.datasets.synthetic.casia_b import (
        CasiaBSynthConfig,
        synthesize_casia_b,
    )

    values = {
        name: getattr(args, option)
        for option, name in (("subjects", "num_subjects"), ("frames", "frames"), ("size", "height"), ("seed", "seed"))
        if getattr(args, option) is not None
    }
    folders = synthesize_casia_b(args.out, CasiaBSynthConfig(**values), progress=not args.quiet, workers=args.workers)
    print(f"[mocapkit] wrote {len(folders)} silhouette sequences (CASIA-B layout) to {args.out}")


def cmd_synth_depth(args: argparse.Namespace) -> None:
    from mocapkit.datasets.synthetic.depth import synthesise_depth

    written, skipped = synthesise_depth(
        args.inputs,
        args.out,
        camera=args.camera,
        noise=args.noise,
        seed=args.seed,
        fps=args.fps,
        format=args.format,
        max_frames=args.max_frames,
        skip_bad=args.skip_bad,
        progress=False if args.quiet else None,
    )
    kind = ".npz files" if args.format == "npz" else "PNG folders"
    print(
        f"[mocapkit] wrote {len(written)} depth sequences ({kind}, camera {args.camera}, "
        f"noise {args.noise or 'the camera preset'}) to {args.out}"
        + "".join(f"\n  {path}" for path in written)
        + "".join(f"\n  skipped {path}: {reason}" for path, reason in skipped)
    )


def cmd_render(args: argparse.Namespace) -> None:
    from mocapkit.visualization.render import render_file

    options = {k: v for k, v in (("view", args.view), ("fps", args.fps), ("n", args.frames)) if v is not None}
    if not args.strip:
        options.pop("n", None)
    else:
        options.pop("fps", None)
    out = render_file(args.file, args.out, strip=args.strip, **options)
    print(f"[mocapkit] wrote {out}")


def cmd_prepare_ntu(args: argparse.Namespace) -> None:
    from mocapkit.datasets.ntu.prepare import prepare_ntu

    report = prepare_ntu(
        args.src,
        args.out,
        workers=args.workers,
        skip_bad=args.skip_bad,
        missing_list=args.missing_list,
        max_bodies=args.max_bodies,
        denoise_spread=args.denoise_spread,
        min_body_frames=args.min_body_frames,
        denoise_flicker=args.denoise_flicker,
        progress=not args.quiet,
    )
    print(f"[mocapkit] prepared cache in {args.out}")
    print(report.summary())


def cmd_prepare_casia_b(args: argparse.Namespace) -> None:
    from mocapkit.datasets.casia_b.prepare import parse_gei_size, prepare_casia_b

    report = prepare_casia_b(
        args.src,
        args.out,
        size=parse_gei_size(args.size),
        per=args.per,
        skip_bad=args.skip_bad,
        workers=args.workers,
        subjects=args.subjects,
        fallback_period=args.fallback_period,
        no_period=args.no_period,
        progress=not args.quiet,
    )
    print(f"[mocapkit] prepared GEI cache in {args.out}")
    if args.quiet:  # otherwise prepare_casia_b has printed the summary (every item is in report.txt)
        print(report.summary())


def cmd_pyskl_export(args: argparse.Namespace) -> None:
    from mocapkit.datasets.interop.pyskl import export_pyskl

    summary = export_pyskl(args.cache, args.out, splits=args.splits)
    lists = ", ".join(f"{k} {n}" for k, n in summary["split"].items())
    print(
        f"[mocapkit] wrote {summary['num_samples']} samples ({summary['total_frames']} frames) to {args.out}; "
        f"split: {lists}"
    )


def cmd_pyskl_import(args: argparse.Namespace) -> None:
    from mocapkit.datasets.interop.pyskl import import_pyskl

    report = import_pyskl(
        args.pkl, args.out, skip_bad=args.skip_bad, max_bodies=args.max_bodies, class_names=args.classes
    )
    print(f"[mocapkit] imported {args.pkl} into the cache {args.out}")
    print(report.to_text())


def cmd_gait_report(args: argparse.Namespace) -> None:
    from mocapkit.gait.benchmark import gait_report  # `compare gait` with these options

    gait_report(
        args.data,
        args.out,
        protocols=tuple(args.protocols),
        experiments=tuple(args.experiments),
        overrides=tuple(args.overrides),
        seed=args.seed,
        include_pca_lda=not args.no_pca_lda,
    )


def cmd_train(argv: list[str]) -> None:
    from mocapkit.train.training import main  # Hydra's command line; resume=RUN/last.ckpt continues a run

    main(argv)


def cmd_eval(overrides: list[str]) -> None:
    from mocapkit.evaluation.evaluate import evaluate
    from mocapkit.train.config import pop_override

    ckpt, rest = pop_override(overrides, "ckpt_path")
    if not ckpt:
        raise SystemExit("mocapkit eval: ckpt_path=PATH is required")
    evaluate(ckpt, rest)


def cmd_export(overrides: list[str]) -> None:
    from mocapkit.deploy.export import export_checkpoint
    from mocapkit.train.config import pop_override

    ckpt, rest = pop_override(overrides, "ckpt_path")
    out, rest = pop_override(rest, "out")  # short for export.out
    if not ckpt:
        raise SystemExit("mocapkit export: ckpt_path=PATH is required")
    export_checkpoint(ckpt, out, rest)


def cmd_refine(args: argparse.Namespace) -> None:
    from mocapkit.refinement.apply import refine_file

    report = refine_file(
        args.input,
        _one_of(args, "output", "out", "OUT"),
        args.method,
        overrides=tuple(args.set),
        train=tuple(args.train),
        skip_bad=args.skip_bad,
        repair_outliers=args.repair_outliers,
        onnx=args.onnx,
        screen_outliers=args.screen_outliers,
    )
    print(report.to_text())


def cmd_index(args: argparse.Namespace) -> None:
    from mocapkit.retrieval.index import add_to_index, build_index

    if args.add:
        index, report = add_to_index(
            args.out,
            _one_of(args, "src_path", "src", "SRC"),
            method=args.method,
            overrides=tuple(args.set),
            ckpt=args.ckpt,
            skip_bad=args.skip_bad,
            workers=args.workers,
        )
        print(
            f"[mocapkit] added {len(report['added'])} files to {args.out} ({len(index.files)} now, "
            f"{index.method_name})"
            + (f"; {len(report['duplicates'])} already indexed" if report["duplicates"] else "")
            + (f"; skipped {len(report['skipped'])} (listed in {args.out}/manifest.json)" if report["skipped"] else "")
        )
        return
    index = build_index(
        _one_of(args, "src_path", "src", "SRC"),
        args.out,
        method=args.method,
        overrides=tuple(args.set),
        ckpt=args.ckpt,
        skip_bad=args.skip_bad,
        workers=args.workers,
    )
    print(
        f"[mocapkit] indexed {len(index.files)} files with {index.method_name} into {args.out}"
        + (f"; skipped {len(index.skipped)} (listed in {args.out}/manifest.json)" if index.skipped else "")
    )


def cmd_search(args: argparse.Namespace) -> None:
    import json

    from mocapkit.retrieval.index import search_index

    if args.within:
        from mocapkit.retrieval.index import MotionIndex

        results = MotionIndex.load(args.index).search_within(args.queries, k=args.k, method=args.method)
        if args.json:
            print(json.dumps(results, indent=1))
            return
        for entry in results:
            print(entry["query"])
            for rank, hit in enumerate(entry["results"], 1):
                print(
                    f"  {rank:3d}  {hit['distance']:10.4f}  {hit['start']:9.2f} s - {hit['end']:9.2f} s  {hit['path']}"
                )
        return
    results = search_index(args.index, args.queries, k=args.k, method=args.method, ckpt=args.ckpt)
    if args.json:
        print(json.dumps(results, indent=1))
        return
    for entry in results:
        print(entry["query"])
        for rank, hit in enumerate(entry["results"], 1):
            print(f"  {rank:3d}  {hit['distance']:10.4f}  {hit['path']}")


def cmd_synthesize(args: argparse.Namespace) -> None:
    from mocapkit.synthesis.synthesize import synthesize

    report = synthesize(
        args.inputs,
        args.out,
        n_variants=args.variants,
        n_frames=args.frames,
        seed=args.seed,
        method=args.method,
        motion_type=args.type,
        max_clips=args.max_clips,
        footskate_cleanup=not args.no_footskate,
        overrides=tuple(args.set),
        progress=not args.quiet,
        output_format=args.format,
        window_seconds=args.window,
    )
    print(
        f"[mocapkit] wrote {len(report['variants'])} variants of {len(report['training_clips'])} training clips to "
        f"{args.out} (fit {report['fit_seconds']:.1f} s, {report['sample_seconds_per_motion_second']:.4f} s of "
        f"compute per second of motion)"
    )


def cmd_kinect_fix_train(args: argparse.Namespace) -> None:
    from mocapkit.kinect.kinect_fix import train_kinect_model

    report = train_kinect_model(
        _one_of(args, "inputs", "mocap", "MOCAP"),
        args.out,
        seed=args.seed,
        skip_bad=args.skip_bad,
        noise=args.noise,
        method=args.method,
        overrides=tuple(args.set),
    )
    print(
        f"[mocapkit] Kinect reconstruction model ({report['method']}) of {report['files']} simulated clips "
        f"({report['frames']} frames, "
        f"noise {report['noise']}, "
        f"fit {report['fit_seconds']:.0f} s) written to {report['model']}"
        + "".join(f"\n  skipped {path}: {reason}" for path, reason in report["skipped"])
    )


def cmd_kinect_fix_export(args: argparse.Namespace) -> None:
    from mocapkit.kinect.kinect_fix import export_kinect_model

    report = export_kinect_model(args.model, args.out)
    print(
        f"[mocapkit] ONNX Kinect corrector written to {report['onnx']} (opset {report['opset']}, "
        f"{report['exporter']} exporter; onnxruntime against PyTorch on {report['checked_shape']}: max |diff| "
        f"{report['max_abs_diff']:.2e} m)"
    )


def cmd_kinect_fix_apply(args: argparse.Namespace) -> None:
    from mocapkit.kinect.kinect_fix import fix_kinect_files

    report = fix_kinect_files(
        args.model, args.inputs, args.out, skip_bad=args.skip_bad, plot=args.plot, overrides=tuple(args.set)
    )
    print(report.to_text())


def cmd_depth_track(args: argparse.Namespace) -> None:
    from mocapkit.depth_tracking.depth_track import track_depth_files

    overrides = list(args.set)
    given = {item.split("=", 1)[0].strip() for item in overrides}
    for flag in ("start", "skeleton"):
        value = getattr(args, flag)
        if value is None:
            continue
        if flag in given:
            raise ValueError(f"mocapkit depth-track: give {flag} once, as --{flag} or as --set {flag}=..., not both")
        overrides.append(f"{flag}={value}")
    report = track_depth_files(
        args.inputs,
        args.prior,
        out=args.out,
        method=args.method,
        overrides=tuple(overrides),
        camera=args.camera,
        fps=args.fps,
        performer=args.performer,
        format=args.format,
        pictures=args.pictures,
        skip_bad=args.skip_bad,
        progress=not args.quiet,
    )
    print(report.to_text())


def _one_of(args: argparse.Namespace, positional: str, option: str, name: str):
    """The value given positionally or as ``--option`` (the commands take inputs positionally; the older option
    spellings still work): exactly one of them."""
    given = [v for v in (getattr(args, positional), getattr(args, option)) if v not in (None, [])]
    if len(given) != 1:
        raise ValueError(
            f"mocapkit {args.command}: give {name} "
            + (f"once (positionally or as --{option})" if given else f"(positionally or as --{option})")
        )
    return given[0]


def cmd_methods(args: argparse.Namespace) -> None:
    from mocapkit.train.registry import methods_table

    print(methods_table(args.task))


def cmd_predict(args: argparse.Namespace) -> None:
    from mocapkit.recognition.predict import predict_files, print_predictions

    print_predictions(predict_files(args.onnx, args.files, top=args.top))


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mocapkit", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--debug", action="store_true", help="show the traceback of an error (as MOCAPKIT_DEBUG=1 does)"
    )
    sub = parser.add_subparsers(dest="command", required=True)

    synth = sub.add_parser("synth", help="write a synthetic stand-in dataset in a real format")
    synth_sub = synth.add_subparsers(dest="dataset", required=True)
    ntu = synth_sub.add_parser("ntu", help="NTU RGB+D-style .skeleton files")
    ntu.add_argument("--out", required=True, help="output folder")
    ntu.add_argument("--classes", type=int, help="number of action classes")
    ntu.add_argument("--subjects", type=int, help="number of subjects (P001..)")
    ntu.add_argument("--seed", type=int, help="random seed (the output is a function of it)")
    ntu.add_argument("--setups", type=int, nargs="+", help="setup IDs (camera height/distance)")
    ntu.add_argument("--cameras", type=int, nargs="+", help="camera IDs (views)")
    ntu.add_argument("--replications", type=int, nargs="+", help="replication IDs")
    ntu.add_argument(
        "--set", action="append", metavar="KEY=VALUE", help="any other synthesis option (difficulty knobs), repeatable"
    )
    ntu.add_argument("--workers", type=int, default=1)
    ntu.add_argument("--quiet", action="store_true", help="no progress bar")
    ntu.set_defaults(func=cmd_synth_ntu)

    hdm = synth_sub.add_parser("hdm05", help="HDM05-style ASF/AMC clips (<class>_<actor>_<nnn>.amc)")
    hdm.add_argument("--out", required=True, help="output folder")
    hdm.add_argument("--classes", nargs="+", help="HDM05 class names (default: a set exercising the merges)")
    hdm.add_argument("--actors", nargs="+", help="actors among bd bk dg mm tr (default: all five)")
    hdm.add_argument("--clips-per-actor", dest="clips_per_actor", type=int, help="takes per class and actor")
    hdm.add_argument("--seed", type=int, help="random seed (the output is a function of it)")
    hdm.add_argument("--quiet", action="store_true", help="no progress bar")
    hdm.set_defaults(func=cmd_synth_hdm05)

    casia = synth_sub.add_parser("casia-b", help="CASIA-B-style silhouette PNGs (<subject>/<cond>-<nn>/<view>/)")
    casia.add_argument("--out", required=True, help="output folder")
    casia.add_argument("--subjects", type=int, help="number of subjects (001..; default 8)")
    casia.add_argument("--frames", type=int, help="frames per sequence (default 40)")
    casia.add_argument("--size", type=int, help="image height in pixels (width = 4/3 of it; default 64)")
    casia.add_argument("--seed", type=int, help="random seed (the output is a function of it)")
    casia.add_argument("--workers", type=int, default=1, help="parallel processes (same output)")
    casia.add_argument("--quiet", action="store_true", help="no progress bar")
    casia.set_defaults(func=cmd_synth_casia_b)

    depth = synth_sub.add_parser(
        "depth", help="depth video (+ colour, part labels, joints) of mocap files, with a depth-sensor noise model"
    )
    depth.add_argument(
        "inputs", nargs="+", metavar="MOCAP", help="mocap files and/or folders (ASF/AMC, BVH, C3D), recursively"
    )
    depth.add_argument("--out", required=True, help="output folder: <name>.npz or <name>/ per input")
    depth.add_argument(
        "--camera", default="kinect_v1", help="kinect_v1 (320x240, default), azure_kinect (640x576) or a camera.yaml"
    )
    depth.add_argument(
        "--noise",
        choices=("kinect_v1", "azure_kinect", "none"),
        default=None,
        help="depth-sensor noise model (default: the camera's; kinect_v1 for a camera.yaml)",
    )
    depth.add_argument(
        "--format", choices=("npz", "png"), default="npz", help="one .npz per take (default) or a folder of PNGs"
    )
    depth.add_argument("--seed", type=int, default=0, help="random seed (the output is a function of it; default 0)")
    depth.add_argument("--fps", type=float, default=30.0, help="frame rate the motions are resampled to (default 30)")
    depth.add_argument("--max-frames", dest="max_frames", type=int, help="render at most the first N frames of each")
    depth.add_argument("--skip-bad", dest="skip_bad", action="store_true", help="skip (and list) unusable files")
    depth.add_argument("--quiet", action="store_true", help="no progress bar")
    depth.set_defaults(func=cmd_synth_depth)

    render = sub.add_parser("render", help="draw a motion file as an animation (.gif, .mp4) or a PNG strip")
    render.add_argument("file", help="any supported motion file (.skeleton, .amc, .bvh, .c3d, MSR .txt)")
    render.add_argument("--out", required=True, help="anim.gif, anim.mp4 (needs ffmpeg) or strip.png")
    render.add_argument("--strip", action="store_true", help="write a PNG strip of evenly spaced frames")
    render.add_argument("--frames", type=int, help="frames in the strip (default 8)")
    render.add_argument("--view", choices=["3d", "front", "side", "top"], help="projection (default 3d)")
    render.add_argument("--fps", type=float, help="animation frame rate (default: at most 15)")
    render.set_defaults(func=cmd_render)

    prepare = sub.add_parser("prepare", help="parse a dataset folder into a memory-mappable cache")
    prepare_sub = prepare.add_subparsers(dest="dataset", required=True)
    pntu = prepare_sub.add_parser("ntu", help="a folder tree of NTU .skeleton files")
    pntu.add_argument("--src", required=True, help="folder of .skeleton files (searched recursively)")
    pntu.add_argument("--out", required=True, help="cache folder to write")
    pntu.add_argument("--workers", type=int, default=1, help="parallel parser processes")
    pntu.add_argument("--skip-bad", action="store_true", help="skip malformed files (each is listed in the report)")
    pntu.add_argument("--missing-list", help="official list of samples with missing skeletons to leave out")
    pntu.add_argument("--max-bodies", type=int, default=2, help="bodies kept per sample (most motion first)")
    pntu.add_argument(
        "--denoise-spread",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="drop non-human 'bodies' wider than tall (the NTU authors' spread rule); on by default, "
        "--denoise-spread is accepted and changes nothing",
    )
    pntu.add_argument(
        "--min-body-frames",
        type=int,
        default=12,
        help="drop bodies seen in fewer frames, never the longest of a file (default 12, the NTU "
        "authors' and pyskl's; 1 disables)",
    )
    pntu.add_argument(
        "--denoise-flicker",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="drop bodies that come and go (< 80%% of the frames of their span) or jump (> 0.3 m a "
        "frame); on by default. The former default was --min-body-frames 1 "
        "--no-denoise-spread --no-denoise-flicker",
    )
    pntu.add_argument("--quiet", action="store_true", help="no progress bar")
    pntu.set_defaults(func=cmd_prepare_ntu)

    pcb = prepare_sub.add_parser("casia-b", help="CASIA-B silhouette folders -> Gait Energy Images")
    pcb.add_argument("--src", required=True, help="root of <subject>/<condition>-<nn>/<view>/<frame>.png")
    pcb.add_argument("--out", required=True, help="GEI cache folder to write")
    pcb.add_argument(
        "--size",
        default="64x44",
        help="GEI HxW: 64x44 (OpenGait's convention, default) or 124x124 (the thesis network)",
    )
    pcb.add_argument(
        "--per",
        choices=["cycle", "sequence"],
        default="cycle",
        help="one GEI per detected gait cycle (default) or per sequence",
    )
    pcb.add_argument(
        "--no-period",
        dest="no_period",
        choices=["sequence", "fallback", "error"],
        default=None,
        help="a sequence without a detectable gait period gives one GEI over the whole sequence "
        "(sequence, the default), GEIs of --fallback-period frames (fallback), or is bad "
        "(error: stops, or is skipped with --skip-bad; the former behaviour); each is reported",
    )
    pcb.add_argument(
        "--fallback-period",
        dest="fallback_period",
        type=int,
        help="frames per cycle to use where no period is detected (implies --no-period fallback; each use is reported)",
    )
    pcb.add_argument("--subjects", type=int, nargs="+", help="only these subject IDs")
    pcb.add_argument("--workers", type=int, default=1, help="parallel processes")
    pcb.add_argument("--skip-bad", action="store_true", help="skip bad sequences (each is listed in the report)")
    pcb.add_argument("--quiet", action="store_true", help="no progress bar")
    pcb.set_defaults(func=cmd_prepare_casia_b)

    pyskl = sub.add_parser("pyskl", help="convert between NTU caches and pyskl / MMAction2 annotation pickles")
    pyskl_sub = pyskl.add_subparsers(dest="direction", required=True)
    pexp = pyskl_sub.add_parser("export", help="write an NTU cache as a pyskl 3D annotation pickle")
    pexp.add_argument("--cache", required=True, help="NTU cache folder (mocapkit prepare ntu --out ...)")
    pexp.add_argument("--out", required=True, help="the .pkl file to write")
    pexp.add_argument(
        "--splits",
        choices=["ntu60", "ntu120"],
        help="split lists: xsub/xview (ntu60) or xsub/xset (ntu120); default: ntu120 when the cache "
        "has NTU-120 setups or actions, else ntu60",
    )
    pexp.set_defaults(func=cmd_pyskl_export)
    pimp = pyskl_sub.add_parser("import", help="write a pyskl 3D annotation pickle as an NTU cache")
    pimp.add_argument("--pkl", required=True, help="pyskl annotation pickle (read without running code)")
    pimp.add_argument("--out", required=True, help="cache folder to write")
    pimp.add_argument("--skip-bad", action="store_true", help="skip bad annotations (each is listed in the report)")
    pimp.add_argument("--max-bodies", type=int, default=2, help="bodies per sample; an annotation with more is bad")
    pimp.add_argument("--classes", help="classes.txt with the action names (line k = action k+1)")
    pimp.set_defaults(func=cmd_pyskl_import)

    for name, help_text in (
        ("train", "train a model (Hydra overrides)"),
        ("eval", "evaluate a checkpoint: ckpt_path=PATH [overrides]"),
        ("export", "export a checkpoint to ONNX: ckpt_path=PATH [out=FILE]"),
        ("compare", ("run configs/compare/NAME.yaml: methods x protocols x seeds (NAME [overrides])")),
    ):
        p = sub.add_parser(name, help=help_text)
        p.add_argument("overrides", nargs="*", help="key=value overrides")

    report = sub.add_parser(
        "gait-report",
        help="multi-task CNN, single-task CNN and GEI+PCA+LDA side by side "
        "under the closed-set and cross-subject CASIA-B protocols",
    )
    report.add_argument("--data", required=True, help="GEI cache (mocapkit prepare casia-b --out ...)")
    report.add_argument("--out", required=True, help="report folder (runs go to OUT/runs)")
    report.add_argument(
        "--protocols", nargs="+", default=["closed_set", "cross_subject"], choices=["closed_set", "cross_subject"]
    )
    report.add_argument(
        "--experiments",
        nargs="+",
        default=["casiab_multitask", "casiab_single_subject"],
        help="Hydra experiments to train (task: gait)",
    )
    report.add_argument("--seed", type=int, default=0, help="run seed")
    report.add_argument("--no-pca-lda", dest="no_pca_lda", action="store_true", help="skip the classical baseline")
    report.add_argument("overrides", nargs="*", help="Hydra overrides for every run, e.g. trainer.max_epochs=30")
    report.set_defaults(func=cmd_gait_report)

    refine = sub.add_parser("refine", help="fill the gaps of a motion file (C3D in, C3D out: only the gaps change)")
    refine.add_argument("input", help="any motion file read_motion reads (.c3d, .amc, .bvh, .skeleton, MSR .txt)")
    refine.add_argument(
        "output", nargs="?", help="OUT.c3d (markers; from a C3D only the filled samples change) or OUT.npz (or --out)"
    )
    refine.add_argument("--out", default=None, help="the output, as the positional OUT")
    which = refine.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--method",
        help="a refinement method (mocapkit methods refinement: linear, pchip, pca, trnn, "
        "...); or RUN/best.ckpt, a trained refiner "
        "(mocapkit train experiment=refine_bigru)",
    )
    which.add_argument(
        "--onnx",
        metavar="FILE",
        help="an exported refiner (mocapkit export of a refiner run), run with onnxruntime and numpy only",
    )
    refine.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a parameter of the method, Hydra's grammar (extrapolate=hold, outlier_threshold=null), "
        "repeatable; trained refiners: window, overlap, repair_threshold, max_empty_frames",
    )
    refine.add_argument(
        "--train",
        action="append",
        default=[],
        metavar="PATH",
        help="clean training motions (file or folder) for data-driven methods, repeatable",
    )
    refine.add_argument(
        "--repair-outliers",
        dest="repair_outliers",
        action="store_true",
        help="also replace the observed samples a robust method flags as outliers (default: only the gaps are filled)",
    )
    refine.add_argument(
        "--screen-outliers",
        dest="screen_outliers",
        nargs="?",
        type=float,
        default=None,
        const=True,
        metavar="METRES",
        help="hide the observed samples farther than METRES from their joint's running median "
        "(noise, spikes; without METRES: mocapkit.refinement.screening.SCREEN_THRESHOLD) and "
        "refill them with the method; implies --repair-outliers",
    )
    refine.add_argument(
        "--skip-bad", dest="skip_bad", action="store_true", help="skip unreadable training files (each is reported)"
    )
    refine.set_defaults(func=cmd_refine)

    index = sub.add_parser("index", help="index a folder of motion files for query by example (mocapkit search)")
    index.add_argument(
        "src_path", nargs="?", metavar="SRC", help="folder searched recursively for files read_motion reads (or --src)"
    )
    index.add_argument("--src", default=None, help="the folder, as the positional SRC")
    index.add_argument("--out", required=True, help="the index folder to write (manifest.json + state.npz)")
    index.add_argument(
        "--method",
        default=None,
        help="a retrieval method (mocapkit methods retrieval; default: the registry's, "
        "dtw_world_frame, the recommended label-free method)",
    )
    index.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help='a parameter of the method, Hydra\'s grammar (window=0.1, "features=[positions]"), repeatable',
    )
    index.add_argument("--ckpt", default=None, help="--method embedding: RUN/best.ckpt or an exported model.onnx")
    index.add_argument(
        "--skip-bad",
        dest="skip_bad",
        action="store_true",
        help="skip files that cannot be read or used (each is reported)",
    )
    index.add_argument(
        "--workers", type=int, default=1, help="processes that read the files and normalise their skeletons"
    )
    index.add_argument(
        "--add",
        action="store_true",
        help="append the files under SRC to the existing index --out without rebuilding it (its method and "
        "parameters; files already indexed are skipped with a message)",
    )
    index.set_defaults(func=cmd_index)

    search = sub.add_parser("search", help="rank the files of an index for each query motion file")
    search.add_argument("--index", required=True, help="a folder written by mocapkit index")
    search.add_argument("queries", nargs="+", help="query motion files")
    search.add_argument("-k", type=int, default=10, help="results per query (0: every indexed file)")
    search.add_argument(
        "--json", action="store_true", help='print [{"query": path, "results": [{"path", "distance"}, ...]}, ...]'
    )
    search.add_argument("--method", default=None, help="refuse unless the index was built with this method")
    search.add_argument("--ckpt", default=None, help="refuse unless the index was built with this model file")
    search.add_argument(
        "--within",
        action="store_true",
        help="find the query inside the indexed files (long takes): the k best segments over all files, "
        'each (file, start s, end s, distance); --json prints {"path", "start", "end", "distance"}',
    )
    search.set_defaults(func=cmd_search)

    synthesize = sub.add_parser(
        "synthesize",
        help="new variants of a motion type from about ten example AMC or BVH clips "
        "(Zhou 2014 ch. 4 SLFM Gaussian processes)",
    )
    synthesize.add_argument(
        "inputs",
        nargs="+",
        help="AMC or BVH files and/or folders (searched recursively); the "
        "ASF is looked up beside each AMC; BVH clips are converted to "
        "ASF/AMC on one T-pose rest",
    )
    synthesize.add_argument(
        "--type",
        default=None,
        metavar="SUBSTRING",
        help="keep only files whose name contains this, e.g. hopBothLegs1hops",
    )
    synthesize.add_argument(
        "--out",
        required=True,
        help="output folder: variant_000.amc ... and the reference .asf (or variant_000.bvh ...), report.json",
    )
    synthesize.add_argument(
        "--format",
        default=None,
        choices=["amc", "bvh"],
        help="variants as ASF/AMC (with the reference skeleton) or self-contained BVH (default: the inputs' format)",
    )
    synthesize.add_argument("--variants", type=int, default=10, help="variants to write (default 10)")
    synthesize.add_argument(
        "--frames", type=int, default=None, help="frames per variant (default: mean training length)"
    )
    synthesize.add_argument("--seed", type=int, default=0, help="seed of the fit and the sampling (default 0)")
    synthesize.add_argument(
        "--max-clips",
        dest="max_clips",
        type=int,
        default=10,
        help="use the first N matching clips, sorted by path (default 10, as the thesis)",
    )
    synthesize.add_argument(
        "--window",
        type=float,
        default=None,
        metavar="SECONDS",
        help="cut each file into consecutive windows of this length and train on the first "
        "--max-clips of them (long takes of one motion, e.g. CMU walks)",
    )
    synthesize.add_argument(
        "--method",
        default=None,
        help="a synthesis method (mocapkit methods synthesis; default slfm; perlin, lau and cvae are the baselines)",
    )
    synthesize.add_argument(
        "--no-footskate",
        dest="no_footskate",
        action="store_true",
        help="skip the footskate cleanup that every method applies (stances, root shift, two-bone leg IK)",
    )
    synthesize.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a parameter of the synthesiser, Hydra's grammar, repeatable, e.g. n_inducing=64, "
        "max_iter=50, frame_stride=4, sample_noise=false, dynamic_feature=scf_difference",
    )
    synthesize.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    synthesize.set_defaults(func=cmd_synthesize)

    kinect = sub.add_parser(
        "kinect-fix",
        help="correct noisy Kinect skeletons (Zhou 2014 ch. 5: GP offset prior, temporal and reliability terms)",
    )
    kinect_sub = kinect.add_subparsers(dest="action", required=True)
    ktrain = kinect_sub.add_parser("train", help="fit a model on simulated Kinect pairs of real mocap files")
    ktrain.add_argument(
        "inputs",
        nargs="*",
        metavar="MOCAP",
        help="mocap files and/or folders (ASF/AMC, BVH, C3D with body landmarks), searched recursively (or --mocap)",
    )
    ktrain.add_argument("--mocap", nargs="+", default=None, help="the mocap files and/or folders, as MOCAP")
    ktrain.add_argument("--out", required=True, help="the model file (.npz for gp, e.g. .pt for the learned ones)")
    ktrain.add_argument(
        "--method",
        default=None,
        help="a kinect method (mocapkit methods kinect) that saves a model; default: the registry's "
        "default (configs/kinect/method.yaml); gp / zhou_thesis: Zhou ch. 5's GP reconstructor; "
        "bigru / transformer: the learned refiner networks retrained as correctors",
    )
    ktrain.add_argument("--seed", type=int, default=0, help="simulation and model seed (default 0)")
    ktrain.add_argument(
        "--noise",
        default=None,
        help="the Kinect simulator's calibration: real_sensor (the default: real Kinect skeletons' "
        "frame-to-frame statistics), mean_error (raw error only) or msr_steadiness",
    )
    ktrain.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a parameter of the model, Hydra's grammar, repeatable, e.g. gp_input=posture, "
        'energy_unit=0.1, max_train_frames=5000 (gp); steps=2000, "network={hidden: 16}" '
        "(bigru, transformer)",
    )
    ktrain.add_argument("--skip-bad", dest="skip_bad", action="store_true", help="skip (and list) unusable files")
    ktrain.set_defaults(func=cmd_kinect_fix_train)
    kexport = kinect_sub.add_parser(
        "export",
        help="write a learned corrector (--method bigru|transformer) as ONNX, "
        "run by `kinect-fix apply --model FILE.onnx` with onnxruntime",
    )
    kexport.add_argument("--model", required=True, help="a learned corrector from `mocapkit kinect-fix train`")
    kexport.add_argument("--out", required=True, help="the .onnx file to write")
    kexport.set_defaults(func=cmd_kinect_fix_export)
    kapply = kinect_sub.add_parser(
        "apply",
        help="correct Kinect skeleton files (MSR Action3D .txt, NTU .skeleton, "
        "C3D) with a trained model; writes OUT/<name>.c3d + report.json",
    )
    kapply.add_argument("inputs", nargs="+", help="Kinect skeleton files and/or folders (searched recursively)")
    kapply.add_argument(
        "--model", required=True, help="a model from `mocapkit kinect-fix train`, or an .onnx from `kinect-fix export`"
    )
    kapply.add_argument("--out", required=True, help="output folder")
    kapply.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a prediction parameter, Hydra's grammar, repeatable: w_spatial, w_temporal, "
        "w_reliability, energy_unit, "
        "reliability, kappa, jump_threshold, still_threshold (gp); inference_window, overlap "
        "(bigru, transformer)",
    )
    kapply.add_argument(
        "--plot", type=int, default=0, metavar="N", help="draw the first N files before/after as PNG strips (default 0)"
    )
    kapply.add_argument(
        "--skip-bad",
        dest="skip_bad",
        action="store_true",
        help="skip (and list) unreadable files, empty files and skeletons without the 20 joints",
    )
    kapply.set_defaults(func=cmd_kinect_fix_apply)

    dtrack = sub.add_parser(
        "depth-track",
        help="track the 16 body joints in depth videos (Lou 2012 ch. 3: model fitting with a mocap prior); "
        "writes OUT/<name>.c3d, <name>_frames.png + report.json",
    )
    dtrack.add_argument(
        "inputs",
        nargs="+",
        metavar="DEPTH",
        help="depth sequences: .npz files, folders of 16-bit PNGs (depth/ + camera.yaml, or bare PNGs with "
        "--camera), and folders of them",
    )
    dtrack.add_argument("--out", required=True, help="output folder")
    dtrack.add_argument(
        "--prior",
        nargs="+",
        default=None,
        metavar="MOCAP",
        help="mocap files and/or folders (ASF/AMC, BVH, C3D), recursively: the motion prior's database; "
        "without it the tracker runs with prior=none",
    )
    dtrack.add_argument(
        "--method", default="tracker", help="a depth_tracking method (mocapkit methods); default tracker"
    )
    dtrack.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a parameter of the method, Hydra's grammar, repeatable, e.g. iterations=5, device=cuda, "
        "use_colour=false, prior_weight=0.01",
    )
    dtrack.add_argument(
        "--camera",
        default=None,
        help="the camera for every input: kinect_v1, azure_kinect or a camera.yaml (needed for bare PNG "
        "folders; overrides a file's own)",
    )
    dtrack.add_argument("--fps", type=float, default=None, help="frame rate of every input (overrides the file's)")
    dtrack.add_argument(
        "--performer", default=None, metavar="MOCAP_FILE", help="a mocap file of the performer: their bone lengths"
    )
    dtrack.add_argument(
        "--start",
        choices=("sensor", "standing", "ground_truth"),
        default=None,
        help="first frame's pose: from the sensor skeleton (the method's default), standing facing the camera "
        "(no sensor skeleton needed), or the ground truth (synthetic data)",
    )
    dtrack.add_argument(
        "--skeleton",
        choices=("sensor", "template", "ground_truth"),
        default=None,
        help="bone lengths: from the sensor skeleton (the method's default), a template body (no sensor "
        "skeleton needed) or the ground truth",
    )
    dtrack.add_argument("--format", choices=("c3d", "bvh"), default="c3d", help="output motion format (default c3d)")
    dtrack.add_argument(
        "--pictures", type=int, default=4, metavar="N", help="frames in each <name>_frames.png (default 4; 0: none)"
    )
    dtrack.add_argument(
        "--skip-bad",
        dest="skip_bad",
        action="store_true",
        help="skip (and list) unreadable or unusable depth sequences and prior files",
    )
    dtrack.add_argument("--quiet", action="store_true", help="no progress bars")
    dtrack.set_defaults(func=cmd_depth_track)

    methods = sub.add_parser(
        "methods",
        help="list the registered methods of every task (or of TASK): name, learned "
        "(needs a trained model), description",
    )
    methods.add_argument(
        "task",
        nargs="?",
        default=None,
        help="recognition, gait, clustering, refinement, retrieval, synthesis, kinect or depth_tracking",
    )
    methods.set_defaults(func=cmd_methods)

    predict = sub.add_parser("predict", help="classify motion files with an exported ONNX model")
    predict.add_argument("--onnx", required=True, help="model written by `mocapkit export`")
    predict.add_argument("--top", type=int, default=5, help="classes printed per file")
    predict.add_argument("files", nargs="+", help="motion files (.skeleton, or any format read_motion reads)")
    predict.set_defaults(func=cmd_predict)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    global _DEBUG
    _DEBUG = False
    while argv and argv[0] == "--debug":  # the global flag, before the command
        _DEBUG = True
        argv.pop(0)
    parser = build_parser()
    # train / eval / export take free-form Hydra overrides, which argparse must not interpret; `train` takes
    # Hydra's flags too (--help lists the config groups, --cfg job prints the config).
    if argv and (argv[0] == "train" or argv[0] in ("eval", "export") and not ({"-h", "--help"} & set(argv[1:]))):
        handler = {"train": cmd_train, "eval": cmd_eval, "export": cmd_export}[argv[0]]
        return _run(handler, argv[1:])
    if argv and argv[0] == "compare":  # `mocapkit compare NAME [overrides]`: Hydra overrides, like train
        from mocapkit.evaluation.compare import cli_main

        return _run(cli_main, argv[1:])
    args = parser.parse_args(argv)
    return _run(args.func, args)


#: ``mocapkit --debug ...``: let errors propagate with their traceback (also ``MOCAPKIT_DEBUG=1``).
_DEBUG = False


def _debug() -> bool:
    return _DEBUG or os.environ.get("MOCAPKIT_DEBUG", "") not in ("", "0")


def _one_line(exc: BaseException) -> str:
    """The error's message on one line (Hydra's and OmegaConf's span several)."""
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    text = "; ".join(lines) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename is not None and str(exc.filename) not in text:
        text = f"{exc.filename}: {text}"
    return text if len(text) <= 2000 else text[:2000] + " ..."


def _user_errors() -> tuple[type[BaseException], ...]:
    """Errors reported as ``mocapkit: error: MESSAGE`` (exit code 2): their messages name the file, key or value."""
    from mocapkit.datasets.formats.errors import MotionFormatError

    errors: list[type[BaseException]] = [MotionFormatError, OSError, ValueError]
    try:
        from mocapkit.train.config import ConfigError

        errors.append(ConfigError)
    except ImportError:  # pragma: no cover - only without hydra installed
        pass
    try:
        from omegaconf.errors import OmegaConfBaseException

        errors.append(OmegaConfBaseException)
    except ImportError:  # pragma: no cover
        pass
    if "mocapkit.deploy.export" in sys.modules:
        errors.append(sys.modules["mocapkit.deploy.export"].ParityError)
    return tuple(errors)


def _run(handler, arg) -> int:
    """Run a command; an error is one line on stderr and exit code 2 (the traceback only with ``--debug``)."""
    try:
        handler(arg)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:
        if _debug():
            raise
        if isinstance(exc, _user_errors()):
            print(f"mocapkit: error: {_one_line(exc)}", file=sys.stderr)
        else:  # not one of ours: still one line, with its type (a bug to report, with the --debug traceback)
            print(f"mocapkit: error: {type(exc).__name__}: {_one_line(exc)} (unexpected)", file=sys.stderr)
        print("(set MOCAPKIT_DEBUG=1 or run mocapkit --debug ... for the traceback)", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
