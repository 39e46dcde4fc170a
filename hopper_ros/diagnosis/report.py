"""Reports of a diagnosis: markdown + PNG for a researcher, JSON for a program."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .core import location_line, timing_line
from .data import PHASES


def _fmt(x):
    return "-" if x is None or not np.isfinite(x) else f"{x:.3g}"


def _num(x):
    return None if x is None or not math.isfinite(float(x)) else float(x)


def _finite(value):
    """JSON has no inf or nan: they become null."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


def _entry(r: dict) -> dict:
    c = r["candidate"]
    entry = {"name": c.name, "kind": c.kind, "family": c.family, "site": c.site, "magnitude": _num(r["magnitude"]),
             "unit": c.unit, "words": c.describe(r["value"]), "equation": c.equation}
    if c.discovery is not None:
        entry["terms"] = [{"term": key, "coefficient": coef * r["value"], "unit": unit, "words": words}
                          for key, coef, words, unit in c.discovery.terms()]
    if c.held:
        entry["secondary"] = [{"name": k, "value": v, "unit": u} for k, (v, u) in c.held.items()]
    return entry


def verdict_entries(result: dict) -> list[dict]:
    """The accepted effects as plain data (what --json writes under "verdict")."""
    out = []
    for r in result["chosen"]:
        c = r["candidate"]
        entry = _entry(r)
        entry.update({"held_out_trajectory_reduction": r["reduction"],
                      "not_separable_from": [t["name"] for t in r.get("ties", [])],
                      "look_alikes": [_entry(t) for t in r.get("ties", [])],
                      "to_separate": sorted({c.separate, *(t["candidate"].separate for t in r.get("ties", []))}
                                            - {""})})
        out.append(entry)
    return out


def _location_entries(locations, threshold):
    return [{"phase": loc.phase, "direction": loc.direction, "site": loc.site, "window": loc.window,
             "size": loc.size, "unit": loc.unit, "over_noise": loc.ratio, "above_noise": loc.ratio >= threshold,
             "basis": loc.basis}
            for loc in locations]


def write_json(result: dict, path: Path) -> Path:
    threshold = result["settings"].locate_threshold
    entries = verdict_entries(result)
    # held-out next-apex errors before and after each accepted effect (cumulative)
    before = result["before"]
    for entry, r in zip(entries, result["chosen"]):
        entry["held_out_before"] = before
        entry["held_out_after"] = r["errors"]
        before = r["errors"]
    doc = {"recording": str(result["data"].rec.source), "strides": len(result["data"].strides),
           "verdict": entries, "summary": result["verdict"],
           "location": _location_entries(result["location"], threshold),
           "held_out": {"before": result["before"], "after": result["after"]},
           "stance_begins_before_model_touchdown_s": result["data"].touchdown_lead,
           "model_effects": result.get("model_effects", {})}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_finite(doc), indent=2, allow_nan=False), encoding="utf-8")
    return path


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
                        label="model + accepted effects" if i == 0 else None)
    for ax, v in zip(axes, ("y", "z", "theta")):
        sig = data.sigma[v] * 1e3
        ax.axhspan(-3 * sig, 3 * sig, color="grey", alpha=0.3, label="+-3 noise std")
        ax.set_ylabel(f"{v} residual [{'mrad' if v == 'theta' else 'mm'}]")
    axes[0].legend(loc="upper left", fontsize=8)
    axes[-1].set_xlabel("time from touchdown [ms]")
    axes[0].set_title(f"{Path(rec.source).name}: {result['verdict']}"[:110], fontsize=9)
    fig.tight_layout()
    png = out / "diagnosis.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)

    threshold = result["settings"].locate_threshold
    lines = [f"# Diagnosis of {rec.source}", "", f"**{result['verdict']}**", "",
             f"{len(s)} strides ({'labelled' if s.labelled else 'phases detected'}); noise std estimated from flight "
             f"samples: y {data.sigma['y'] * 1e3:.3f} mm, z {data.sigma['z'] * 1e3:.3f} mm, "
             f"theta {data.sigma['theta'] * 1e3:.3f} mrad.", "",
             "## 1. Where the model and the recording differ", "",
             location_line(result["location"], threshold), "", timing_line(data), "",
             "By force: residual forces at the measured state (recording minus model, the smoothing's bias removed "
             "with a clean twin of the recording made by the model), against what noise alone produces (a noisy "
             "twin). By fit: the change acting at the site that, fitted on training strides, removes most of the "
             "held-out residual (its t over strides, scaled so that the guard's t is the threshold):", "",
             "| phase | direction | basis | window | size | over noise |", "|---|---|---|---|---|---|"]
    for loc in result["location"]:
        lines.append(f"| {loc.phase} | {loc.direction} | {loc.basis} | {loc.window} | {loc.size:+.3g} {loc.unit} "
                     f"| {loc.ratio:.1f} |")
    lines += ["", "## 2. Candidates (held-out ranking)", ""]
    for k, ranking in enumerate(result["rounds"]):
        lines += [f"Round {k + 1}" + (" (on top of the effects accepted before)" if k else "") + ":", "",
                  "| candidate | kind | fitted magnitude | held-out SSE reduction | t | held-out E_p/E_v/E_t % | verdict |",
                  "|---|---|---|---|---|---|---|"]
        for r in ranking[:12]:
            c = r["candidate"]
            e = r["errors"]
            mag = c.describe(r["value"]) if c.kind == "discovered" else f"{r['magnitude']:.4g} {c.unit}"
            why = "accepted" if r["significant"] else "; ".join(r["rejected"])
            lines.append(f"| {c.name} | {c.kind} | {mag} | {100 * r['reduction']:.1f} % | {r['t']:.1f} | "
                         f"{e['E_p']:.2f}/{e['E_v']:.2f}/{e['E_t']:.2f} | {why} |")
        lines.append("")
    for entry in verdict_entries(result):
        lines += [f"**{entry['name']}** ({entry['kind']}, {entry['site']}): {entry['words']}"
                  + (f"; law {entry['equation']}" if entry["equation"] else "")]
        if entry["not_separable_from"]:
            lines += [f"Not separable on this data from {', '.join(entry['not_separable_from'])}; to separate them: "
                      + "; ".join(entry["to_separate"]) + "."]
        lines.append("")
    lines += ["## 3. The model with the accepted effects", "", "RMS residual per phase before -> after (m, m, rad):", "",
              "| phase | y | z | theta |", "|---|---|---|---|"]
    for ph in PHASES:
        b, a = result["before_phase"][ph], result["after_phase"][ph]
        lines.append(f"| {ph} | " + " | ".join(f"{_fmt(b[v])} -> {_fmt(a[v])}" for v in ("y", "z", "theta")) + " |")
    bf, af = result["before"], result["after"]
    lines += ["", "Held-out next-apex errors (magnitudes fitted without the stride's fold):", "",
              "| | E_p % | E_v % | E_t % |", "|---|---|---|---|",
              f"| model | {bf['E_p']:.3f} | {bf['E_v']:.3f} | {bf['E_t']:.3f} |",
              f"| model + accepted | {af['E_p']:.3f} | {af['E_v']:.3f} | {af['E_t']:.3f} |", "",
              "After the accepted effects: " + location_line(result["residual_location"], threshold), "",
              "![residuals](diagnosis.png)", ""]
    md = out / "diagnosis.md"
    md.write_text("\n".join(lines), encoding="utf-8")
    return md
