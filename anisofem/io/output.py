"""Files written atomically (to a temporary file in the destination's folder, then renamed over
the destination, so that a reader, or a run interrupted mid-write, never sees half a file), and
where the commands write their results by default: the folder results/ of the current
directory."""
import contextlib
import json
import os
import tempfile

RESULTS = "results"
SCRATCH = "out"


def result_path(name):
    """The default path of a result file `name` (e.g. "bench_anisofem.json"): results/name."""
    return os.path.join(RESULTS, name)


def scratch_path(name):
    """The default path of what a run made to look at a result writes (a swing, the robustness
    grid): out/name, beside the examples' pictures; the copy in results/ that the docs quote is
    rewritten only when a run is told to (--json results/NAME)."""
    return os.path.join(SCRATCH, name)


@contextlib.contextmanager
def atomic_path(path, suffix=""):
    """Yield a temporary path next to `path` (ending in suffix; its folder made when missing);
    on a clean exit rename it to `path` with the permissions of a newly created file, on an
    error remove it."""
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=suffix, dir=folder)
    os.close(fd)
    try:
        yield tmp
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0o600
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def check_folder(path, name="path"):
    """FileNotFoundError naming `name` unless the folder of path exists or can be made (its
    nearest existing ancestor is a folder); writing through atomic_path makes it."""
    folder = os.path.dirname(os.path.abspath(os.fspath(path)))
    while not os.path.exists(folder):
        folder = os.path.dirname(folder)
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"{name}: the folder of {os.fspath(path)!r} cannot be made "
                                f"({folder!r} is a file)")


def write_json(path, obj):
    """Write obj as indented JSON to path atomically (numpy scalars as floats)."""
    with atomic_path(path, ".json") as tmp, open(tmp, "w") as f:
        json.dump(obj, f, indent=1, default=float)


def publish(report, printer, out):
    """printer(report), then report written to out as JSON unless out is None, and where it
    went said; returns report."""
    printer(report)
    if out:
        write_json(out, report)
        print(f"\nwrote {out}")
    return report
