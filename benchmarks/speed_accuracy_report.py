"""The speed-accuracy report's Markdown tables, Pareto choice and plots (from results.json)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - after the backend is chosen

from core.atomic import atomic_output  # noqa: E402
from data_schema.metrics_doc import NOTHING_MOVES  # noqa: E402


def table(rows: list[dict], cols: list[tuple[str, str, str]]) -> str:
    """A Markdown table of ``rows``: columns (key, header, format); a missing value is '-'."""
    head = "| " + " | ".join(h for _, h, _ in cols) + " |"
    lines = [head, "|" + "---|" * len(cols)]
    for r in rows:
        cells = [format(r[k], f) if k in r else "-" for k, _, f in cols]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


ACC = [("ld_mm", "mean L_d [mm]", ".3f"), ("ld_max_mm", "max L_d [mm]", ".2f"),
       ("force_n", "force abs. error [N]", ".3f")]
SPEED = [("force26_ms", "force only, 26 pts, known mesh [ms]", ".3f"),
         ("full26_ms", "full, 26 pts [ms]", ".3f"), ("full1024_ms", "full, 1024 pts [ms]", ".2f")]


def pareto(rows: list[dict], cost: str, error: str) -> list[dict]:
    """The rows no other row beats on both ``cost`` and ``error``, cheapest first."""
    ok = [r for r in rows if cost in r and error in r]
    front = [r for r in ok if not any(o[cost] <= r[cost] and o[error] <= r[error]
                                      and (o[cost], o[error]) != (r[cost], r[error]) for o in ok)]
    return sorted(front, key=lambda r: r[cost])


REGION = [("points", "points", "d"), ("setting", "region", "s"),
          ("ld_mm", "L_d vs truth [mm]", ".3f"), ("force_n", "force error [N]", ".3f"),
          ("ld_vs_whole_mm", "L_d vs whole model [mm]", ".3f"),
          ("force_vs_whole_n", "force vs whole [N]", ".3f"), ("ms", "latency [ms]", ".2f")]


NOTHING = f"{NOTHING_MOVES} (reference)"


def region_text(region: dict) -> str:
    """The region-of-interest rows, each size's Pareto front (latency against L_d), and the
    default radius they support."""
    pick_mm, tol = region["default_mm"], region["tolerance"]
    parts = [table(region["rows"], REGION)]
    for n in sorted({r["points"] for r in region["rows"]}):
        front = pareto([r for r in region["rows"] if r["points"] == n], "ms", "ld_mm")
        parts.append(f"Pareto front at {n} points (latency against L_d): "
                     + ", ".join(f"{r['setting']} ({r['ms']:.2f} ms, {r['ld_mm']:.3f} mm)"
                                 for r in front) + ".\n")
    parts.append(f"Default radius (mean L_d within {tol:.0%} of the whole model's at every "
                 f"size): {'none of these' if pick_mm is None else f'{pick_mm:g} mm'}.\n")
    ld = {(r["points"], r["setting"]): r["ld_mm"] for r in region["rows"]}
    idle = [n for n, s in ld if s == "whole model"
            and ld[(n, s)] > (1 - tol) * ld.get((n, NOTHING), float("inf"))]
    if idle:
        parts.append(f"**Not evidence:** at {idle} points the whole model's mean L_d is within "
                     f"{tol:.0%} of '{NOTHING}': it learned no displacement to lose, so no "
                     "radius can change its L_d. Judge the radius by the force columns.\n")
    return "\n".join(parts)


EXTREME_FLAGS = [("flagged", "flagged", ".0%"), ("refused", "refused", ".0%")]
ANSWER = [("dforce_n", "mean abs. dF [N]", ".3f"), ("disp_mm", "mean max displacement [mm]", ".3f")]


def extremes_text(ext: dict) -> str:
    """The extremes' tables (``benchmarks/extremes.py``): frame offsets, press sizes, depth
    and point orderings, each with the share of calls the predictor flagged or refused."""
    return "\n".join([
        "Frame offsets (points and C shifted; errors against the shifted truth):\n",
        table(ext["offset"], [("test", "shift", "s"), *ACC[::2], *EXTREME_FLAGS]),
        "Press size (the press vector scaled about the tip's start; 0 must give exactly 0):\n",
        table(ext["press"], [("factor", "x measured press", "g"), *ANSWER, *ACC[::2],
                             *EXTREME_FLAGS]),
        "Depth (the tip driven straight down from its start; the phantom is 32 mm thick):\n",
        table(ext["depth"], [("depth_mm", "depth [mm]", "g"), *ANSWER, *EXTREME_FLAGS]),
        "Point order (5 random orders of each example, answers put back in order):\n",
        table(ext["ordering"], [("model", "model", "s"), ("points", "points", "d"),
                                ("max_point_mm", "largest point change [mm]", ".2e"),
                                ("max_force_n", "largest force change [N]", ".2e")]),
    ])


def pick(rows: list[dict], cost: str, budget: float, error: str, tie: float = 0.02
         ) -> dict | None:
    """The most accurate row whose ``cost`` fits ``budget``; among rows within ``tie``
    (relative) of the best error, the cheapest (a difference that small is noise)."""
    fits = [r for r in rows if cost in r and error in r and r[cost] <= budget]
    if not fits:
        return None
    best = min(r[error] for r in fits)
    return min((r for r in fits if r[error] <= best * (1 + tie)), key=lambda r: r[cost])


def choice_text(rows: list[dict], haptic_ms: float, visual_ms: float) -> str:
    """Which setting to pick for the haptic loop and for visuals, and why."""
    h = pick(rows, "force26_ms", haptic_ms, "force_n")
    v = pick(rows, "full1024_ms", visual_ms, "ld_mm")
    lines = []
    lines.append(f"- 1 kHz haptic loop (force only, 26 points, budget {haptic_ms:g} ms): " + (
        f"**{h['setting']}** ({h['force26_ms']:.3f} ms, force error {h['force_n']:.3f} N)"
        if h else "no setting fits on this machine"))
    lines.append(f"- 60 Hz visuals (displacements of 1024 points, budget {visual_ms:.1f} ms): " + (
        f"**{v['setting']}** ({v['full1024_ms']:.2f} ms, L_d {v['ld_mm']:.3f} mm)"
        if v else "no setting fits on this machine"))
    return "\n".join(lines) + "\n"


def write_report(out: Path, res: dict, haptic_ms: float, visual_ms: float) -> None:
    """``out/report.md`` and its plots."""
    choices = res["k"] + res["precision"][1:] + res.get("augmented", [])   # [0]: k=5 again
    b = res["budget"]
    md = [f"# Speed-accuracy report\n\nMeasured on {res['device']} in one run. Twin rows: "
          f"cGNN/Exp, fold 0, {b['twin_epochs']} epochs, lr {b['lr']:g}; MSM rows: "
          f"{b['msm_grid']}x{b['msm_grid']} grid, {b['msm_locations']} locations x "
          f"{b['msm_directions']} directions, {b['msm_epochs']} epochs. Latency: median "
          f"batch-1 wall time. Errors on the fold's test examples.\n",
          "## Which setting\n", choice_text(choices, haptic_ms, visual_ms),
          "## k (neighbours per point)\n", table(res["k"], [("setting", "k", "s"), *ACC, *SPEED]),
          "\n## Fraction of points per training sample\n",
          table(res["fraction"], [("setting", "setting", "s"), *ACC,
                                  ("epoch_s", "s / epoch", ".2f")]),
          "\n## Precision (k = 5)\n", table(res["precision"], [("setting", "", "s"), *ACC,
                                                              *SPEED]),
          "\n## Number of points (MSM model)\n",
          table(res["points"], [("points", "points", "d"), ("full_ms", "full [ms]", ".3f"),
                                ("force_ms", "force only [ms]", ".3f"), *ACC]),
          "\n## Region of interest (MSM model, `Predictor.predict(..., region=R)`)\n",
          region_text(res["region"]) if "region" in res else "not measured\n",
          "\n## Rotation augmentation (k = 5, `pipeline train --rotate`)\n",
          table(res.get("augmented", []), [("setting", "setting", "s"), *ACC, *SPEED]),
          "\n## Robustness (twin test set moved or resampled)\n",
          table(res["robustness"], [("model", "model", "s"), ("test", "test set", "s"), *ACC,
                                    ("force_ratio", "force error ratio", ".2f"),
                                    ("ld_ratio", "L_d ratio", ".2f")]),
          "\n## At the extremes (twin model through `train.Predictor`)\n",
          extremes_text(res["extremes"]) if "extremes" in res else "not measured\n",
          "\n## MSM solver tolerance\n",
          table(res["msm_tolerance"], [("solver", "solver", "s"), ("tol", "tolerance", ".0e"),
                                       ("ms", "ms / example", ".2f"),
                                       ("max_err_mm", "max error [mm]", ".2e")]),
          "\n## Pareto fronts\n\nLatency of the full model at 26 points against L_d:\n\n",
          table(pareto(choices, "full26_ms", "ld_mm"), [("setting", "setting", "s"), *SPEED,
                                                         *ACC]),
          "\nLatency of the force head at 26 points against the force error:\n\n",
          table(pareto(choices, "force26_ms", "force_n"), [("setting", "setting", "s"),
                                                            *SPEED, *ACC]),
          "\nPlots: `k.png`, `points.png`, `pareto.png`, `robustness.png`.\n"]
    with atomic_output(out / "report.md") as tmp:
        Path(tmp).write_text("\n".join(md))
    plot_k(out / "k.png", res["k"])
    plot_points(out / "points.png", res["points"], haptic_ms, visual_ms)
    plot_pareto(out / "pareto.png", choices)
    plot_robustness(out / "robustness.png", res["robustness"])


def save(fig: plt.Figure, path: Path) -> None:
    """Write a figure atomically and close it."""
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def plot_k(path: Path, rows: list[dict]) -> None:
    """Errors and latency against k, one quantity per panel."""
    k = [r["k"] for r in rows]
    fig, ax = plt.subplots(1, 3, figsize=(11, 3.2))
    for a, key, label in ((ax[0], "ld_mm", "mean L_d [mm]"),
                          (ax[1], "force_n", "force abs. error [N]"),
                          (ax[2], "full26_ms", "latency, 26 points [ms]")):
        a.plot(k, [r[key] for r in rows], "o-", color="tab:blue")
        a.set_xlabel("k (neighbours)")
        a.set_ylabel(label)
        a.set_xticks(k)
        a.grid(alpha=0.3)
    save(fig, path)


def plot_points(path: Path, rows: list[dict], haptic_ms: float, visual_ms: float) -> None:
    """Latency against the number of points (log-log), with the two budgets."""
    n = [r["points"] for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.loglog(n, [r["full_ms"] for r in rows], "o-", color="tab:blue", label="full model")
    ax.loglog(n, [r["force_ms"] for r in rows], "s--", color="tab:orange", label="force only")
    ax.axhline(haptic_ms, color="tab:red", lw=1, label=f"1 kHz haptics ({haptic_ms:g} ms)")
    ax.axhline(visual_ms, color="tab:green", lw=1, label=f"60 Hz frame ({visual_ms:.1f} ms)")
    ax.set_xlabel("points")
    ax.set_ylabel("batch-1 latency [ms]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    save(fig, path)


def plot_pareto(path: Path, rows: list[dict]) -> None:
    """Each setting's latency at 26 points against its L_d, the front joined."""
    fig, ax = plt.subplots(figsize=(6, 4))
    for r in (r for r in rows if "ld_mm" in r):
        ax.plot(r["full26_ms"], r["ld_mm"], "o", color="tab:blue")
        ax.annotate(r["setting"], (r["full26_ms"], r["ld_mm"]), fontsize=8,
                    xytext=(4, 4), textcoords="offset points")
    front = pareto(rows, "full26_ms", "ld_mm")
    ax.plot([r["full26_ms"] for r in front], [r["ld_mm"] for r in front], "-",
            color="tab:gray", lw=1, label="Pareto front")
    ax.set_xlabel("latency, 26 points [ms]")
    ax.set_ylabel("mean L_d [mm]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save(fig, path)


def plot_robustness(path: Path, rows: list[dict]) -> None:
    """Per test set, plain against augmented: the force error (N) and its ratio to the
    model's own error on the unmoved test set."""
    tests = list(dict.fromkeys(r["test"] for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(12, 3.8))
    width = 0.4
    for ax, key, label in ((axes[0], "force_n", "force abs. error [N]"),
                           (axes[1], "force_ratio", "force error / unmoved")):
        for i, (model, color) in enumerate((("plain", "tab:blue"),
                                            ("rotation-augmented", "tab:orange"))):
            value = {r["test"]: r[key] for r in rows if r["model"] == model}
            ax.bar([t + (i - 0.5) * width for t in range(len(tests))],
                   [value[t] for t in tests], width, color=color, label=model)
        ax.set_xticks(range(len(tests)), [t.replace(" about the normal", "") for t in tests],
                      rotation=15, fontsize=8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, axis="y")
    axes[1].axhline(1.2, color="tab:red", lw=1, label="goal under rotation (1.2x)")
    axes[1].legend(fontsize=8)
    save(fig, path)
