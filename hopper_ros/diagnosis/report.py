"""Markdown + PNG report of a diagnosis."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .core import PHASES


def _fmt(x):
    return "-" if x is None or not np.isfinite(x) else f"{x:.3g}"


def write_report(result: dict, out: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    data = result["data"]
    s, rec = data.strides, data.rec
    fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
    for i, (sb, sa) in enumerate(zip(result["base_series"], result["after_series"])):
        a, b = int(s.start[i]), int(s.stop[i])
        tk = rec.t[a:b] - s.touchdown_time[i]
        for ax, v in zip(axes, ("y", "z", "theta")):
            ax.plot(tk * 1e3, sb[v][0] * 1e3, color="tab:red", lw=0.5, alpha=0.5, label="model" if i == 0 else None)
            if result["chosen"]:
                ax.plot(tk * 1e3, sa[v][1] * 1e3, color="tab:blue", lw=0.5, alpha=0.5,
                        label="model + chosen effects" if i == 0 else None)
    for ax, v in zip(axes, ("y", "z", "theta")):
        sig = data.sigma[v] * 1e3
        ax.axhspan(-3 * sig, 3 * sig, color="grey", alpha=0.3, label="+-3 noise std")
        ax.set_ylabel(f"{v} residual [{'mrad' if v == 'theta' else 'mm'}]")
    axes[0].legend(loc="upper left", fontsize=8)
    axes[-1].set_xlabel("time from touchdown [ms]")
    axes[0].set_title(f"{Path(rec.source).name}: {result['verdict']}")
    fig.tight_layout()
    png = out / "diagnosis.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)

    loc = result["locate"]
    lines = [f"# Diagnosis of {rec.source}", "", f"**Verdict: {result['verdict']}**", "",
             f"{len(s)} strides ({'labelled' if s.labelled else 'phases detected'}); noise std estimated from flight "
             f"samples: y {data.sigma['y'] * 1e3:.3f} mm, z {data.sigma['z'] * 1e3:.3f} mm, "
             f"theta {data.sigma['theta'] * 1e3:.3f} mrad; residual correlation length {data.corr_length:.0f} samples.",
             "", "## 1. Where the model and the recording differ", "",
             f"Largest: **{loc['where'][1]} in {loc['where'][0]}**, RMS {loc['ratio']:.1f} x the noise; the residual "
             f"first exceeds 3 noise std at a median {loc['onset'] * 1e3:.0f} ms after the apex.", "",
             "RMS residual per phase (model as given; m, m/s, rad):", "",
             "| phase | y | z | y' | z' | theta |", "|---|---|---|---|---|---|"]
    for ph in PHASES:
        row = loc["table"][ph]
        lines.append(f"| {ph} | " + " | ".join(_fmt(row[v]) for v in ("y", "z", "ydot", "zdot", "theta")) + " |")
    lines += ["", "## 2. Candidate effects (held-out ranking)", ""]
    for k, ranking in enumerate(result["rounds"]):
        lines += [f"Round {k + 1}" + (" (on top of the effects chosen before)" if k else "") + ":", "",
                  "| candidate | fitted magnitude | held-out SSE reduction | t over strides | CV dBIC | significant |",
                  "|---|---|---|---|---|---|"]
        for r in ranking:
            c = r["candidate"]
            lines.append(f"| {c.name} ({c.words}) | {r['magnitude']:.4g} {c.unit} | {100 * r['reduction']:.1f} % | "
                         f"{r['t']:.1f} | {r['delta_bic']:.1f} | {'yes' if r['significant'] else 'no'} |")
        lines.append("")
    if result["sparse"]:
        lines += ["Sparse regression of the remaining stance residual acceleration (fall-back):", ""]
        lines += [f"- {w}" for w in result["sparse"]] + [""]
    lines += ["## 3. Model with the chosen effects", "", "RMS residual per phase before -> after (y, z, theta):", "",
              "| phase | y | z | theta |", "|---|---|---|---|"]
    for ph in PHASES:
        b, a = result["before_phase"][ph], result["after_phase"][ph]
        lines.append(f"| {ph} | " + " | ".join(f"{_fmt(b[v])} -> {_fmt(a[v])}" for v in ("y", "z", "theta")) + " |")
    bf, af = result["before"], result["after"]
    lines += ["", "Held-out next-apex errors (magnitudes fitted without the stride's fold):", "",
              "| | E_p % | E_v % | E_t % |", "|---|---|---|---|",
              f"| model | {bf['E_p']:.3f} | {bf['E_v']:.3f} | {bf['E_t']:.3f} |",
              f"| model + chosen | {af['E_p']:.3f} | {af['E_v']:.3f} | {af['E_t']:.3f} |", "",
              "![residuals](diagnosis.png)", ""]
    md = out / "diagnosis.md"
    md.write_text("\n".join(lines), encoding="utf-8")
    return md
