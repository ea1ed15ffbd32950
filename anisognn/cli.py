"""`python -m anisognn train --config FILE [--out DIR]` and `python -m anisognn bench`."""
import argparse
import sys

from . import bench, train


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m anisognn")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("train", help="train (or resume) a model from a TOML config")
    p.add_argument("--config", required=True, help="TOML file with [model], [sampler], [train]")
    p.add_argument("--out", help="output folder (overrides [train] out)")
    p.add_argument("--iterations", type=int, help="overrides [train] iterations")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p = sub.add_parser("bench", help="time the network, the loss and a training iteration")
    p.add_argument("--json", default="bench_anisognn.json", help="where to write the JSON")
    args = parser.parse_args(argv)
    if args.command == "train":
        overrides = {k: v for k, v in (("out", args.out), ("iterations", args.iterations))
                     if v is not None}
        try:
            config = train.load_config(args.config, **overrides)
            _, summary = train.train(config, progress=not args.no_progress)
        except (ValueError, FileNotFoundError, train.TrainingDiverged) as err:
            sys.exit(f"error: {err}")
        if summary["rank"] == 0:
            print(f"done: {summary['iterations']} iterations, final loss {summary['final_loss']:.6g}"
                  f" J, model in {config.train.out}/model.pt")
    else:
        bench.run(out=args.json)
