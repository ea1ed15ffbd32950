"""`python -m anisognn train --config FILE [--out DIR] [--seed N]`, `python -m anisognn evaluate
MODEL...` and `python -m anisognn bench`."""
import argparse
import os
import sys

from anisofem.io.output import result_path

from . import bench, evaluate, shipped, train
from .model import with_galerkin


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m anisognn")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("train", help="train (or resume) a model from a TOML config")
    p.add_argument("--config", required=True, help="TOML file with [model], [sampler], [train]")
    p.add_argument("--out", help="output folder (overrides [train] out)")
    p.add_argument("--iterations", type=int, help="overrides [train] iterations")
    p.add_argument("--seed", type=int, help="overrides [train] seed (samples and initial weights)")
    p.add_argument("--no-progress", action="store_true", help="no progress display")
    p = sub.add_parser("evaluate", help="the evaluation suite against anisofem (paper Tables "
                       "1, 2, Fig. 6), models side by side")
    p.add_argument("models", nargs="+", metavar="MODEL",
                   help=f"a model.pt / checkpoint.pt file or a shipped name {shipped.NAMES}")
    p.add_argument("--steps", type=int, default=evaluate.STEPS,
                   help="rollout steps per scene (default %(default)s)")
    p.add_argument("--json", default=result_path("evaluation.json"),
                   help="where to write the JSON (default %(default)s)")
    add_galerkin_arguments(p)
    p = sub.add_parser("bench", help="time the network, the loss and a training iteration")
    p.add_argument("--json", default=result_path("bench_anisognn.json"),
                   help="where to write the JSON (default %(default)s)")
    args = parser.parse_args(argv)
    if args.command == "train":
        overrides = {k: v for k, v in (("out", args.out), ("iterations", args.iterations),
                                       ("seed", args.seed)) if v is not None}
        try:
            config = train.load_config(args.config, **overrides)
            _, summary = train.train(config, progress=not args.no_progress)
        except (ValueError, FileNotFoundError, train.TrainingDiverged) as err:
            sys.exit(f"error: {err}")
        if summary["rank"] == 0:
            print(f"done: {summary['iterations']} iterations, final loss {summary['final_loss']:.6g}"
                  f" J, model in {config.train.out}/model.pt")
    elif args.command == "evaluate":
        try:
            models = {_label(m): stepping(shipped.model(m), args) for m in args.models}
        except (ValueError, FileNotFoundError) as err:
            sys.exit(f"error: {err}")
        evaluate.run(models, steps=args.steps, out=args.json)
    else:
        bench.run(out=args.json)


def add_galerkin_arguments(parser):
    """--galerkin on|off, --galerkin-passes K and --cg-iterations J on parser: how a model
    steps, whatever its config says (read back by stepping)."""
    parser.add_argument("--galerkin", choices=("on", "off"),
                        help="take the Galerkin step (on) or the network's own acceleration "
                        "(off), whatever the model's config says (default: as it says)")
    parser.add_argument("--galerkin-passes", type=int, metavar="K",
                        help="Galerkin passes per step (implies --galerkin on; default: the "
                        "model's own, 1 for a model without the step): each pass costs about "
                        "half the network's step on 100 tets")
    parser.add_argument("--cg-iterations", type=int, metavar="J",
                        help="conjugate-gradient iterations on the backward-Euler step after "
                        "the model's own (float64; default: the model's own, 0 for the shipped "
                        "models): more is closer to the FEM, each one Hessian product")


def stepping(model, args):
    """The GraphNet model as args' --galerkin, --galerkin-passes and --cg-iterations ask
    (itself if none)."""
    if args.galerkin is None and args.galerkin_passes is None and args.cg_iterations is None:
        return model
    if args.cg_iterations is not None and args.cg_iterations < 0:
        raise ValueError(f"--cg-iterations: expected an integer >= 0, got {args.cg_iterations}")
    if args.galerkin == "off":
        if args.galerkin_passes is not None:
            raise ValueError("--galerkin-passes: passes of the Galerkin step, which --galerkin "
                             "off leaves out")
        return with_galerkin(model, False, cg_iterations=args.cg_iterations)
    galerkin = model.config.galerkin or args.galerkin == "on" or args.galerkin_passes is not None
    return with_galerkin(model, galerkin, args.galerkin_passes, args.cg_iterations)


def _label(spec):
    """Column name of a model: its shipped name, else its file's folder and name."""
    if spec in shipped.NAMES:
        return spec
    return os.path.join(os.path.basename(os.path.dirname(os.path.abspath(spec))),
                        os.path.basename(spec))
