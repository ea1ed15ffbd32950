"""The trade's result for a person: a text table (`anisofem.trade_table`) and the Pareto plot
of error against cost (`plot`, matplotlib)."""
import math
import os

from ..io.output import atomic_path
from .trade import BUSY_CORES


def trade_table(result):
    """The trade result as a text table."""
    times = "/".join(f"{t:g}" for t in result["times"])
    body = "reference" in result
    vs_body = f"{'vs body':>9}" if body else ""
    head = (f"{'rung':<27} {'ms/step':>8} {'x exact':>8} {'tip error at t = ' + times + ' s':<36}"
            f"{vs_body} {'its':>5} {'drift':>8} {'min J':>7} stable")
    exact = result["rungs"][0]["ms_per_step"]
    lines = [head, "-" * len(head)]
    for r in result["rungs"]:
        errs = " / ".join(f"{e:.2g}" for e in r["errors"])
        its = r.get("iterations_per_step")
        vs_body = f" {r['max_continuum_error']:8.2g}" if body else ""
        mark = "*" if r.get("busy_cores", 0.0) >= BUSY_CORES else " "
        lines.append(f"{r['name']:<27}{mark}{r['ms_per_step']:8.3g} {exact / r['ms_per_step']:8.2f} "
                     f"{errs:<36}{vs_body} {'' if its is None else f'{its:.1f}':>5} "
                     f"{r['energy_drift']:8.1e} {r['min_volume_ratio']:6.2f}"
                     f"{'!' if r.get('inverted') else ' '} {r['stable']}")
    s = result["scene"]
    lines.append(f"{s['tets']} tets, {s['unknowns']} unknowns, dt = {s['dt']} s, {s['steps']} "
                 f"steps; errors relative to the static tip deflection {s['deflection']:.4g} m")
    lines.append("min J: the smallest volume ratio det F of any element at any step (1: none "
                 "compressed); ! marks a rung that turned elements inside out (det F <= 0): "
                 "stable says no step failed and no energy was gained, not that the answer is "
                 "physical")
    rec = result["recommended"]
    lines.append(f"cheapest stable rung within {result['tolerance']:g} at every checked time: "
                 f"{rec if rec else 'none'}")
    if body:
        ref = result["reference"]
        rec = result["recommended_continuum"]
        lines.append(f"vs body: the largest tip error against {ref['name']} ({ref['tets']} tets, "
                     f"order {ref['order']}, {ref['unknowns']} unknowns), over its static "
                     f"deflection {ref['deflection']:.4g} m; cheapest within "
                     f"{result['tolerance']:g} of it: {rec if rec else 'none'}")
    lines += [f"note: {n}" for n in result["notes"]]
    busy = [r for r in result["rungs"] if r.get("busy_cores", 0.0) >= BUSY_CORES]
    if busy:
        lines.append(
            f"warning: the machine was busy: other processes kept up to "
            f"{max(r['busy_cores'] for r in busy):.1f} of {result['machine']['cores']} cores "
            f"busy while {len(busy)} rungs were timed (marked *, timed twice and the calmer "
            f"run kept); their ms/step are slower than on an idle machine")
    return "\n".join(lines)


def _label_positions(ax, rows, y_of, xlim, ylim, reference="exact"):
    """Where the plot's rung labels go, lowest rung first, each moved up while it would overlap
    a label already placed or another rung's marker: ([(text, (x, y) of the rung, (x, y) of
    the label, moved)], the y of the highest label's top), in data coordinates of the log-log
    axes ax with limits xlim, ylim."""
    # sizes in decades: about 6.5 and 11 pixels per character width and line height, markers
    # about 5 pixels across from their centre
    box = ax.get_window_extent()
    char_w = 6.5 * math.log10(xlim[1] / xlim[0]) / box.width
    line_h = 11.0 * math.log10(ylim[1] / ylim[0]) / box.height
    mark_x, mark_y = 5.0 * char_w / 6.5, 5.0 * line_h / 11.0
    markers = [(math.log10(r["ms_per_step"]), math.log10(y_of(r))) for r in rows]
    placed, labels = [], []
    for r in sorted(rows, key=y_of):
        x, y = r["ms_per_step"], y_of(r)
        text = r["name"] + (" (reference)" if r["name"] == reference else "")
        lx, ly, w = math.log10(x) + 1.2 * mark_x, math.log10(y) - 0.4 * line_h, len(text) * char_w

        def hits(ly):
            return any(lx < px + pw and px < lx + w and abs(ly - py) < line_h
                       for px, py, pw in placed) or any(
                lx - mark_x < mx < lx + w + mark_x and ly - mark_y < my < ly + line_h + mark_y
                for mx, my in markers if (mx, my) != (math.log10(x), math.log10(y)))
        start = ly
        while hits(ly):
            ly += 0.5 * line_h
        placed.append((lx, ly, w))
        labels.append((text, (x, y), (10 ** lx, 10 ** ly), ly > start))
    top = max((py for _, py, _ in placed), default=-math.inf) + 1.5 * line_h
    return labels, 10 ** top


def plot(result, path):
    """Save the Pareto plot of a trade result to path (PNG): ms/step against the largest tip
    error over the checked times, log-log, one marker per rung, the front joined."""
    try:
        import matplotlib
    except ImportError:
        raise ImportError("png: the trade plot needs matplotlib (pip install matplotlib)") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    rows = result["rungs"]
    # against the body where the trade has a continuum reference, else against exact
    error = "max_continuum_error" if "reference" in result else "max_error"
    finite = [r[error] for r in rows if 0 < r[error] < math.inf]
    floor = min(finite) / 10 if finite else 1e-6
    ceiling = max(finite) * 10 if finite else 1.0
    fig, ax = plt.subplots(figsize=(10, max(5.5, 2.4 + 0.13 * len(rows))))
    ax.axhline(result["tolerance"], color="0.6", lw=0.8, ls="--")
    def y_of(r):
        return min(max(r[error], floor), ceiling)

    # the front in this plot's two numbers: stable rungs no other is faster and more exact than
    front, best = [], math.inf
    for r in sorted((r for r in rows if r["stable"]), key=lambda r: (r["ms_per_step"],
                                                                     r[error])):
        if r[error] < best:
            front.append(r)
            best = r[error]
    xs = [r["ms_per_step"] for r in front]
    ys = [y_of(r) for r in front]
    ax.step(xs, ys, where="post", color="tab:green", lw=6, alpha=0.25,
            solid_capstyle="round", label="Pareto front")
    styles = {"fem": ("o", "tab:blue", "anisofem"), "reduced": ("D", "tab:purple", "reduced model"),
              "surrogate": ("s", "tab:orange", "surrogate"),
              "discretization": ("^", "tab:brown", "finer mesh, exact")}
    recommended = result.get("recommended_continuum") if error != "max_error" else \
        result["recommended"]
    reference = result["reference"]["name"] if error != "max_error" else "exact"
    ax.set_xscale("log")
    ax.set_yscale("log")
    ms = [r["ms_per_step"] for r in rows]
    xlim = (min(ms) / 1.5, max(ms) * 4)
    ylim = (floor / 2, ceiling * 2)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1, 2, 5)))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.text(xlim[1] / 1.1, result["tolerance"] * 1.1, f"tolerance {result['tolerance']:g}",
            color="0.4", fontsize=8, ha="right")
    shown = set()
    for r in rows:
        marker, color, label = styles[r["kind"]]
        if not r["stable"]:
            marker, color, label = "x", "tab:red", "unstable or failed"
        ax.scatter(r["ms_per_step"], y_of(r), marker=marker, color=color, s=50, zorder=3,
                   label=None if label in shown else label)
        shown.add(label)
        if r["name"] == recommended:
            ax.scatter(r["ms_per_step"], y_of(r), marker="o", s=220, facecolors="none",
                       edgecolors="tab:green", linewidths=2, zorder=4,
                       label=f"recommended (within {result['tolerance']:g}"
                             f"{' of the body' if error != 'max_error' else ''})")
    # each rung marked by its number in the table's order, the numbers' key beside the legend
    numbered = [dict(r, name=str(k)) for k, r in enumerate(rows, 1)]
    labels, top = _label_positions(ax, numbered, y_of, xlim, ylim, reference=None)
    for _ in range(3):  # the axes grow to hold the highest label; the labels are placed anew
        if top <= ylim[1]:
            break
        ylim = (ylim[0], top)
        ax.set_ylim(*ylim)
        labels, top = _label_positions(ax, numbered, y_of, xlim, ylim, reference=None)
    key = "\n".join(f"{k:>2}  {r['name']}" + (" (reference)" if r["name"] == reference else "")
                    for k, r in enumerate(rows, 1))
    ax.text(1.02, 0.0, key, transform=ax.transAxes, fontsize=7, va="bottom", ha="left",
            family="monospace")
    for text, xy, xytext, moved in labels:
        ax.annotate(text, xy, xytext=xytext, fontsize=7.5, va="bottom",
                    arrowprops={"arrowstyle": "-", "color": "0.7", "lw": 0.5} if moved else None)
    ax.set_xlabel("ms per step of dt (this machine, one process)")
    times = ", ".join(f"{t:g}" for t in result["times"])
    against = (f"against {result['reference']['name']}" if error != "max_error"
               else "against the exact step")
    ax.set_ylabel(f"largest tip error {against}\nat t = {times} s (fraction of the static "
                  f"deflection)")
    sc = result["scene"]
    ax.set_title(f"{os.path.basename(sc['name']) or 'scene'}: {sc['tets']:,} tets, "
                 f"dt = {sc['dt']:g} s, {sc['steps']} steps", fontsize=10)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    with atomic_path(path, ".png") as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
