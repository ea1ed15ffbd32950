"""The command line, `python -m anisofem {mesh,solve,trade,fit,design,control,bench}`: the shared
arguments (`arguments`), the parser (`parser`, whose text is the usage), the forward commands
(`commands`) and the inverse ones (`inverse`)."""
from .arguments import BODIES, Parser, add_scene_arguments, body_of, scene_of
from .commands import bench_command, mesh_command, solve_command, trade_command
from .inverse import control_command, design_command, fit_command
from .parser import build_parser

__all__ = ["main", "one_line_warning", "BAD_INPUT", "BODIES", "Parser", "add_scene_arguments",
           "body_of", "scene_of", "build_parser"]

#: What a command's bad input raises: each ends it with one line and exit status 2
BAD_INPUT = (ValueError, TypeError, FileNotFoundError, ImportError)


def one_line_warning(message, category, filename, lineno, line=None):
    """warnings.formatwarning for the command line: "warning: MESSAGE", one line, not the
    source line that raised it."""
    return f"warning: {message}\n"


def main(argv=None):
    """Run a command; bad input ends it with a one-line error and exit status 2, before any
    long work starts."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except BAD_INPUT as err:
        parser.exit(2, f"{parser.prog} {args.command}: error: {err}\n")


COMMANDS = {"mesh": mesh_command, "solve": solve_command, "trade": trade_command,
            "bench": bench_command, "fit": fit_command, "design": design_command,
            "control": control_command}
